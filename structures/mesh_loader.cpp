// Polygon mesh files: OBJ, OFF, STL and PLY with small parsers of our own; OpenMesh's readers as
// an independent second reading (load_mesh_openmesh) that the tests compare them against.
//
// Why not OpenMesh for loading (the design card's first plan): measured on OpenMesh 9.0 (Debian 12),
// its readers change primitive ids, accept broken files silently, or take the process down:
//  - OBJ: a face with a repeated vertex ("f 1 2 2") is dropped, shifting every later triangle id;
//    "v nan 0 0" is skipped, shifting every later vertex index; through TriMesh, non-manifold faces
//    print "complex edge" and get duplicated vertices. It is also ~5x slower than the parser below.
//    (On the shared scenes, which have no such faces, it reads the same triangles: see the tests.)
//  - STL: facets with two equal corners are dropped; a truncated ASCII file loads without complaint.
//  - OFF: '#' comments make the reader run on uninitialised counts (thousands of garbage faces);
//    truncated files yield faces made of stale indices.
//  - PLY: truncated files are padded with stale values and reported as read; one corrupt byte in
//    the header (a non-numeric version or count) makes its header loop print forever; one corrupt
//    byte in an ASCII list length ("-4") makes it allocate until the kernel kills the process.
// Correct ids are the point of a traversal benchmark (hits are compared by primitive id) and bad
// input must be an InputError, so every format gets an exact parser with located messages.
#include <OpenMesh/Core/IO/IOManager.hh>
#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/IO/importer/BaseImporter.hh>
#include <OpenMesh/Core/System/omstream.hh>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <mutex>
#include <sstream>
#include <string_view>
#include <unordered_map>

#include "structures/scene_loader.h"

namespace tb {

namespace {

using detail::error_line;

// ---------------------------------------------------------------------------------------------
// Text helpers shared by the OBJ, OFF, ASCII STL and ASCII PLY parsers.

inline bool is_blank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

// Splits [p, end) into lines; '\r' before '\n' is blank-stripped by the tokenizer. With
// `lone_cr`, a '\r' not followed by '\n' ends a line too (classic Mac OS line ends, which some OBJ
// exporters still write; read as one line, such a file would have no faces). Off for the formats
// whose header parsing also locates binary data (PLY), where a CR must not end the header.
struct LineReader {
  const char* p;
  const char* end;
  bool lone_cr = false;
  size_t line = 0;
  const char* newline = nullptr;  // the next '\n' at or after p (end: none), kept across lines
  bool next(std::string_view& out) {
    if (p >= end) return false;
    if (!newline || newline < p) {  // memchr once per '\n', not once per line: a CR-only file has none
      newline = static_cast<const char*>(std::memchr(p, '\n', static_cast<size_t>(end - p)));
      if (!newline) newline = end;
    }
    const char* eol = newline;
    if (lone_cr)  // a '\r' right before the '\n' is a CRLF line end, left to the tokenizer
      if (const char* cr = static_cast<const char*>(std::memchr(p, '\r', static_cast<size_t>(eol - p))); cr && cr + 1 < eol)
        eol = cr;
    out = std::string_view(p, static_cast<size_t>(eol - p));
    p = eol < end ? eol + 1 : end;
    ++line;
    return true;
  }
};

// Whitespace-separated tokens of one line.
struct Tokens {
  const char* p;
  const char* e;
  explicit Tokens(std::string_view s) : p(s.data()), e(s.data() + s.size()) {}
  bool next(std::string_view& tok) {
    while (p < e && is_blank(*p)) ++p;
    if (p >= e) return false;
    const char* b = p;
    while (p < e && !is_blank(*p)) ++p;
    tok = std::string_view(b, static_cast<size_t>(p - b));
    return true;
  }
};

// Parses a whole token as a float. Accepts a leading '+', which from_chars does not. A value below
// the float range (1e-50) becomes its nearest float (0 or a denormal) instead of an error; one above
// it stays an error, as do "nan"/"inf" (caught by the caller's finiteness check).
bool parse_float(std::string_view tok, float& out) {
  const char* b = tok.data();
  const char* e = b + tok.size();
  if (b < e && *b == '+') ++b;
  auto r = std::from_chars(b, e, out);
  if (r.ec == std::errc::result_out_of_range) {
    double d;
    auto rd = std::from_chars(b, e, d);
    if (rd.ec != std::errc() || rd.ptr != e) return false;
    out = static_cast<float>(d);  // overflow -> inf, rejected by the finiteness check
    return true;
  }
  return r.ec == std::errc() && r.ptr == e;
}

// Parses a leading integer of tok; *rest gets the remainder (for OBJ's "v/vt/vn").
bool parse_int_prefix(std::string_view tok, long long& out, std::string_view* rest) {
  const char* b = tok.data();
  const char* e = b + tok.size();
  if (b < e && *b == '+') ++b;
  auto r = std::from_chars(b, e, out);
  if (r.ec != std::errc()) return false;
  if (rest) *rest = std::string_view(r.ptr, static_cast<size_t>(e - r.ptr));
  else if (r.ptr != e) return false;
  return true;
}

// What may follow a face vertex's position index: nothing, "/vt", "/vt/vn" or "//vn" (the texture
// and normal indices carry no geometry, but a token of another shape, "1////" or "1/x", is a
// malformed file, not a vertex).
bool obj_vertex_suffix_ok(std::string_view rest) {
  if (rest.empty()) return true;
  long long unused;
  std::string_view more;
  rest.remove_prefix(1);  // the '/' the caller checked
  if (!rest.empty() && rest[0] != '/') {  // vt
    if (!parse_int_prefix(rest, unused, &more)) return false;
    rest = more;
    if (rest.empty()) return true;
    if (rest[0] != '/') return false;
  } else if (rest.empty()) {
    return false;  // "v/" names nothing
  }
  rest.remove_prefix(1);  // the second '/': a normal index must follow
  return parse_int_prefix(rest, unused, nullptr);
}

std::string quote(std::string_view s) {
  std::string out = "'";
  for (char c : s.substr(0, 40)) out += (static_cast<unsigned char>(c) < 32 || c == 127) ? '?' : c;
  if (s.size() > 40) out += "...";
  return out + "'";
}

std::string at_line(size_t line) { return "line " + std::to_string(line) + ": "; }

// The x y z that start the rest of an OBJ or OFF vertex line, each a finite float (what follows
// them is the caller's). `number` is the vertex as the format counts it (OBJ from 1, OFF from 0);
// `short_hint` ends the message for a line with fewer than three values.
Vec3 parse_vertex(Tokens& t, const std::string& path, size_t line, size_t number, const char* short_hint) {
  Vec3 p;
  std::string_view tok;
  for (int c = 0; c < 3; ++c) {
    if (!t.next(tok))
      throw InputError(error_line(path, at_line(line) + "vertex needs three coordinates" + short_hint));
    if (!parse_float(tok, p[c]))
      throw InputError(error_line(path, at_line(line) + "vertex coordinate " + quote(tok) + " is not a number"));
  }
  if (!is_finite(p))
    throw InputError(error_line(path, at_line(line) + "vertex " + std::to_string(number) + " has a NaN or Inf coordinate"));
  return p;
}

// Triangle count guard: ids are uint32 and 0xFFFFFFFF means "no hit".
constexpr size_t kMaxElements = 0xFFFFFFFEull;

// ---------------------------------------------------------------------------------------------
// OBJ

Scene parse_obj(const std::string& path, const std::string& data) {
  Scene s;
  s.name = detail::file_stem(path);
  // ~30 bytes per vertex line and per face line in typical files; a rough reservation saves most
  // of the reallocation copies on the 10+ MB scenes.
  s.positions.reserve(data.size() / 64);
  s.triangles.reserve(data.size() / 64);

  LineReader lines{data.data(), data.data() + data.size(), /*lone_cr=*/true};
  std::string_view line, tok;
  std::vector<uint32_t> face;
  long long max_index = -1;  // largest 0-based index seen, checked once all vertices are known
  size_t max_index_line = 0;
  while (lines.next(line)) {
    Tokens t(line);
    if (!t.next(tok)) continue;
    if (tok == "v") {
      // Extra values (w, or the r g b some exporters append) carry no geometry.
      const Vec3 p = parse_vertex(t, path, lines.line, s.positions.size() + 1, " (truncated file?)");
      if (s.positions.size() >= kMaxElements) throw InputError(error_line(path, "more than 2^32-2 vertices"));
      s.positions.push_back(p);
    } else if (tok == "f") {
      face.clear();
      while (t.next(tok)) {
        long long i;
        std::string_view rest;
        if (!parse_int_prefix(tok, i, &rest) || (!rest.empty() && rest[0] != '/'))
          throw InputError(error_line(path, at_line(lines.line) + "face vertex " + quote(tok) + " is not an index"));
        if (!obj_vertex_suffix_ok(rest))
          throw InputError(error_line(path, at_line(lines.line) + "face vertex " + quote(tok) +
                                                " is not v, v/vt, v//vn or v/vt/vn"));
        long long idx;
        if (i > 0) {
          idx = i - 1;
          if (idx >= static_cast<long long>(kMaxElements))
            throw InputError(error_line(path, at_line(lines.line) + "vertex index " + std::to_string(i) + " is too large"));
          // Positive indices may name vertices defined further down (tinyobjloader and most
          // readers allow it), so the range check waits for the end of the file.
          if (idx > max_index) {
            max_index = idx;
            max_index_line = lines.line;
          }
        } else if (i < 0) {
          // Relative index: -1 is the most recently defined vertex.
          idx = static_cast<long long>(s.positions.size()) + i;
          if (idx < 0)
            throw InputError(error_line(path, at_line(lines.line) + "relative vertex index " + std::to_string(i) +
                                                  " points before the first vertex (" +
                                                  std::to_string(s.positions.size()) + " defined so far)"));
        } else {
          throw InputError(error_line(path, at_line(lines.line) + "vertex index 0 is invalid (OBJ indices start at 1)"));
        }
        face.push_back(static_cast<uint32_t>(idx));
      }
      if (face.size() < 3)
        throw InputError(error_line(path, at_line(lines.line) + "face has " + std::to_string(face.size()) +
                                              " vertices, needs at least 3 (truncated file?)"));
      // DESIGN.md: polygon (v0..vn) -> fan (v0, v{i-1}, v{i}) in file order. Degenerate faces
      // are kept so that every later id still matches the file.
      for (size_t i = 2; i < face.size(); ++i) s.triangles.push_back({face[0], face[i - 1], face[i]});
      if (s.triangles.size() > kMaxElements) throw InputError(error_line(path, "more than 2^32-2 triangles"));
    }
    // Everything else (vt, vn, g, o, s, usemtl, mtllib, l, p, comments, ...) carries no triangles.
  }
  if (max_index >= static_cast<long long>(s.positions.size()))
    throw InputError(error_line(path, at_line(max_index_line) + "face uses vertex " + std::to_string(max_index + 1) +
                                          " but the file defines only " + std::to_string(s.positions.size()) +
                                          " vertices"));
  return s;
}

// ---------------------------------------------------------------------------------------------
// OFF (Geomview): "[ST][C][N]OFF" header (optional), "nv nf [ne]", nv vertex lines, nf face lines
// "k i0 .. i{k-1} [colour]". '#' starts a comment. Parsed line by line, as every writer emits it.

// Next non-empty line with its comment removed; false at end of file.
bool next_off_line(LineReader& lines, std::string_view& out) {
  std::string_view l;
  while (lines.next(l)) {
    size_t hash = l.find('#');
    if (hash != std::string_view::npos) l = l.substr(0, hash);
    Tokens t(l);
    std::string_view tok;
    if (t.next(tok)) {
      out = l;
      return true;
    }
  }
  return false;
}

Scene parse_off(const std::string& path, const std::string& data) {
  Scene s;
  s.name = detail::file_stem(path);
  LineReader lines{data.data(), data.data() + data.size()};
  std::string_view line, tok;
  if (!next_off_line(lines, line)) throw InputError(error_line(path, "file holds only comments or blank lines"));

  Tokens t(line);
  t.next(tok);
  long long counts[3] = {0, 0, 0};
  int ncounts = 0;
  std::string_view header = tok;
  const bool has_keyword = header.size() >= 3 && header.substr(header.size() - 3) == "OFF";
  if (has_keyword) {
    std::string_view prefix = header.substr(0, header.size() - 3);
    if (prefix.find_first_not_of("STCN") != std::string_view::npos)
      throw InputError(error_line(path, "OFF variant " + quote(header) + " is not supported (4OFF/nOFF have no 3D triangles)"));
    if (t.next(tok)) {
      if (tok == "BINARY") throw InputError(error_line(path, "binary OFF is not supported; convert it to ASCII OFF or PLY"));
      // Some writers put the counts on the header line.
      t = Tokens(line);
      t.next(tok);
    } else if (!next_off_line(lines, line)) {
      throw InputError(error_line(path, "file ends after the OFF header (no vertex/face counts)"));
    } else {
      t = Tokens(line);
    }
  } else {
    long long dummy;
    if (!parse_int_prefix(tok, dummy, nullptr))
      throw InputError(error_line(path, "not an OFF file (first word " + quote(tok) + ", expected OFF)"));
    t = Tokens(line);  // no keyword: this line holds the counts
  }
  while (ncounts < 3 && t.next(tok)) {
    if (!parse_int_prefix(tok, counts[ncounts], nullptr) || counts[ncounts] < 0)
      throw InputError(error_line(path, at_line(lines.line) + "count " + quote(tok) + " is not a non-negative integer"));
    ++ncounts;
  }
  if (ncounts < 2) throw InputError(error_line(path, at_line(lines.line) + "expected 'vertices faces [edges]' counts"));
  const long long nv = counts[0], nf = counts[1];
  // Each vertex and face takes at least one line of >= 2 bytes; larger counts are a wrong header or
  // a cut file, and must not turn into a huge reservation.
  if (nv > static_cast<long long>(data.size()) || nf > static_cast<long long>(data.size()) - nv)
    throw InputError(error_line(path, "header declares " + std::to_string(nv) + " vertices and " + std::to_string(nf) +
                                          " faces, more than a " + std::to_string(data.size()) +
                                          "-byte file can hold (truncated file or wrong header?)"));
  if (nv >= static_cast<long long>(kMaxElements)) throw InputError(error_line(path, "more than 2^32-2 vertices"));
  s.positions.reserve(static_cast<size_t>(nv));
  s.triangles.reserve(static_cast<size_t>(nf));

  for (long long v = 0; v < nv; ++v) {
    if (!next_off_line(lines, line))
      throw InputError(error_line(path, "file ends after " + std::to_string(v) + " of " + std::to_string(nv) +
                                            " vertices (truncated?)"));
    Tokens vt(line);
    // The vertex count names a truncation already ("file ends after ..."), so no hint here.
    s.positions.push_back(parse_vertex(vt, path, lines.line, static_cast<size_t>(v), ""));
  }
  std::vector<uint32_t> face;
  for (long long f = 0; f < nf; ++f) {
    if (!next_off_line(lines, line))
      throw InputError(error_line(path, "file ends after " + std::to_string(f) + " of " + std::to_string(nf) +
                                            " faces (truncated?)"));
    Tokens ft(line);
    long long k;
    ft.next(tok);
    if (!parse_int_prefix(tok, k, nullptr))
      throw InputError(error_line(path, at_line(lines.line) + "face vertex count " + quote(tok) + " is not an integer"));
    if (k < 3)
      throw InputError(error_line(path, at_line(lines.line) + "face has " + std::to_string(k) + " vertices, needs at least 3"));
    face.clear();
    for (long long i = 0; i < k; ++i) {
      long long idx;
      if (!ft.next(tok))
        throw InputError(error_line(path, at_line(lines.line) + "face lists fewer than its " + std::to_string(k) +
                                              " vertices (truncated?)"));
      if (!parse_int_prefix(tok, idx, nullptr))
        throw InputError(error_line(path, at_line(lines.line) + "face vertex " + quote(tok) + " is not an index"));
      if (idx < 0 || idx >= nv)
        throw InputError(error_line(path, at_line(lines.line) + "vertex index " + std::to_string(idx) +
                                              " is out of range (" + std::to_string(nv) + " vertices)"));
      face.push_back(static_cast<uint32_t>(idx));
    }
    // Remaining tokens are an optional face colour.
    for (size_t i = 2; i < face.size(); ++i) s.triangles.push_back({face[0], face[i - 1], face[i]});
    if (s.triangles.size() > kMaxElements) throw InputError(error_line(path, "more than 2^32-2 triangles"));
  }
  return s;
}

// ---------------------------------------------------------------------------------------------
// STL. Corners are shared by exact bit pattern, as STL has no indices; every facet becomes one
// triangle in file order, degenerate ones included.

struct BitsHash {
  size_t operator()(const std::array<uint32_t, 3>& k) const {
    uint64_t h = k[0] * 0x9E3779B97F4A7C15ull;
    h ^= (k[1] + 0x7F4A7C15ull) * 0xC2B2AE3D27D4EB4Full;
    h ^= (k[2] + 0x165667B1ull) * 0x165667B19E3779F9ull;
    return static_cast<size_t>(h ^ (h >> 29));
  }
};

struct VertexWelder {
  std::unordered_map<std::array<uint32_t, 3>, uint32_t, BitsHash> ids;
  Scene* s;
  uint32_t add(Vec3 p) {
    std::array<uint32_t, 3> key;
    std::memcpy(key.data(), &p, sizeof key);
    auto [it, inserted] = ids.try_emplace(key, static_cast<uint32_t>(s->positions.size()));
    if (inserted) s->positions.push_back(p);
    return it->second;
  }
};

Scene parse_stl_binary(const std::string& path, const std::string& data, uint32_t count) {
  Scene s;
  s.name = detail::file_stem(path);
  s.triangles.reserve(count);
  s.positions.reserve(count / 2 + 3);
  VertexWelder weld{{}, &s};
  weld.ids.reserve(count / 2 + 3);
  const char* rec = data.data() + 84;
  for (uint32_t f = 0; f < count; ++f, rec += 50) {
    std::array<uint32_t, 3> tri;
    for (int c = 0; c < 3; ++c) {
      Vec3 p;
      std::memcpy(&p, rec + 12 + 12 * c, 12);  // little-endian floats, as the format fixes
      if (!is_finite(p))
        throw InputError(error_line(path, "facet " + std::to_string(f) + " has a NaN or Inf coordinate"));
      tri[c] = weld.add(p);
    }
    s.triangles.push_back(tri);
  }
  return s;
}

// ASCII STL tokenizer that keeps line numbers for messages.
struct StlTokens {
  const char* p;
  const char* e;
  size_t line = 1;
  bool next(std::string_view& tok) {
    while (p < e && (is_blank(*p) || *p == '\n')) {
      if (*p == '\n') ++line;
      ++p;
    }
    if (p >= e) return false;
    const char* b = p;
    while (p < e && !is_blank(*p) && *p != '\n') ++p;
    tok = std::string_view(b, static_cast<size_t>(p - b));
    return true;
  }
  void skip_line() {
    while (p < e && *p != '\n') ++p;
  }
};

bool iequals(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i)
    if (std::tolower(static_cast<unsigned char>(a[i])) != std::tolower(static_cast<unsigned char>(b[i]))) return false;
  return true;
}

Scene parse_stl_ascii(const std::string& path, const std::string& data) {
  Scene s;
  s.name = detail::file_stem(path);
  VertexWelder weld{{}, &s};
  StlTokens t{data.data(), data.data() + data.size()};
  std::string_view tok;
  // A binary STL whose 80-byte header happens to start with "solid" and whose size does not match
  // its count lands here; say so instead of reporting a confusing token.
  const bool looks_binary = std::memchr(data.data(), '\0', std::min<size_t>(data.size(), 4096)) != nullptr;
  auto fail = [&](const std::string& what) -> InputError {
    if (looks_binary)
      return InputError(error_line(path, "binary STL whose header starts with 'solid' but whose size does not match "
                                         "its triangle count (truncated?)"));
    return InputError(error_line(path, at_line(t.line) + what));
  };
  auto expect = [&](std::string_view word) {
    if (!t.next(tok)) throw fail("file ends where '" + std::string(word) + "' was expected (truncated?)");
    if (!iequals(tok, word)) throw fail("expected '" + std::string(word) + "', found " + quote(tok));
  };

  if (!t.next(tok) || !iequals(tok, "solid")) throw fail("ASCII STL must start with 'solid'");
  t.skip_line();  // solid name
  for (;;) {
    if (!t.next(tok)) throw fail("file ends without 'endsolid' (truncated?)");
    if (iequals(tok, "endsolid")) {
      t.skip_line();
      // Some tools concatenate several solids in one file.
      if (t.next(tok)) {
        if (!iequals(tok, "solid")) throw fail("expected 'solid' or end of file after 'endsolid', found " + quote(tok));
        t.skip_line();
        continue;
      }
      break;
    }
    if (!iequals(tok, "facet")) throw fail("expected 'facet' or 'endsolid', found " + quote(tok));
    expect("normal");
    // The stored normal is not needed (and some writers emit "nan" there): skip its 3 values.
    for (int i = 0; i < 3; ++i)
      if (!t.next(tok)) throw fail("file ends inside a facet normal (truncated?)");
    expect("outer");
    expect("loop");
    std::array<uint32_t, 3> tri;
    for (int c = 0; c < 3; ++c) {
      expect("vertex");
      Vec3 p;
      for (int k = 0; k < 3; ++k) {
        if (!t.next(tok)) throw fail("file ends inside a vertex (truncated?)");
        if (!parse_float(tok, p[k])) throw fail("vertex coordinate " + quote(tok) + " is not a number");
      }
      if (!is_finite(p)) throw fail("vertex has a NaN or Inf coordinate");
      tri[c] = weld.add(p);
    }
    if (!t.next(tok)) throw fail("file ends inside a facet (truncated?)");
    if (iequals(tok, "vertex")) throw fail("facet with more than 3 vertices; only triangles are valid STL");
    if (!iequals(tok, "endloop")) throw fail("expected 'endloop', found " + quote(tok));
    expect("endfacet");
    s.triangles.push_back(tri);
    if (s.triangles.size() > kMaxElements) throw InputError(error_line(path, "more than 2^32-2 triangles"));
  }
  return s;
}

Scene parse_stl(const std::string& path, const std::string& data) {
  size_t first = 0;
  while (first < data.size() && (is_blank(data[first]) || data[first] == '\n')) ++first;
  const bool starts_solid = data.compare(first, 5, "solid") == 0;
  if (data.size() >= 84) {
    uint32_t count;
    std::memcpy(&count, data.data() + 80, 4);
    const uint64_t expected = 84 + 50ull * count;
    if (expected == data.size()) return parse_stl_binary(path, data, count);
    if (!starts_solid) {
      if (expected > data.size())
        throw InputError(error_line(path, "binary STL declares " + std::to_string(count) + " triangles (" +
                                              std::to_string(expected) + " bytes) but the file has " +
                                              std::to_string(data.size()) + " bytes (truncated?)"));
      return parse_stl_binary(path, data, count);  // trailing padding after the last facet is ignored
    }
  }
  if (!starts_solid)
    throw InputError(error_line(path, "not an STL file (no 'solid' header and too short for binary STL)"));
  return parse_stl_ascii(path, data);
}

// ---------------------------------------------------------------------------------------------
// PLY: header (strict) and body (ASCII, binary little/big endian; any element/property layout; the
// vertex element's x, y, z and the face element's vertex_indices list are kept).

enum class PlyType { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64 };

struct PlyProperty {
  std::string name;
  PlyType type;                  // value type (of the entries, for a list)
  bool list = false;
  PlyType count_type = PlyType::UInt8;
};

struct PlyElement {
  std::string name;
  uint64_t count = 0;
  std::vector<PlyProperty> props;
};

struct PlyHeader {
  enum Format { Ascii, BinaryLE, BinaryBE } format = Ascii;
  std::vector<PlyElement> elements;
  size_t body = 0;  // byte offset of the first element
  const PlyElement* find(const std::string& name) const {
    for (const auto& e : elements)
      if (e.name == name) return &e;
    return nullptr;
  }
};

bool ply_type(const std::string& t, PlyType& out) {
  static const std::pair<const char*, PlyType> kTypes[] = {
      {"char", PlyType::Int8},     {"int8", PlyType::Int8},       {"uchar", PlyType::UInt8},
      {"uint8", PlyType::UInt8},   {"short", PlyType::Int16},     {"int16", PlyType::Int16},
      {"ushort", PlyType::UInt16}, {"uint16", PlyType::UInt16},   {"int", PlyType::Int32},
      {"int32", PlyType::Int32},   {"uint", PlyType::UInt32},     {"uint32", PlyType::UInt32},
      {"float", PlyType::Float32}, {"float32", PlyType::Float32}, {"double", PlyType::Float64},
      {"float64", PlyType::Float64}};
  for (const auto& [name, type] : kTypes)
    if (t == name) {
      out = type;
      return true;
    }
  return false;
}

size_t ply_size(PlyType t) {
  switch (t) {
    case PlyType::Int8:
    case PlyType::UInt8: return 1;
    case PlyType::Int16:
    case PlyType::UInt16: return 2;
    case PlyType::Int32:
    case PlyType::UInt32:
    case PlyType::Float32: return 4;
    case PlyType::Float64: return 8;
  }
  return 1;
}

bool is_ply_name(const std::string& t) {
  if (t.empty()) return false;
  for (char c : t)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.')) return false;
  return true;
}

// Strict on purpose: besides our own reader, the header also gates OpenMesh's (load_mesh_openmesh),
// whose header parser reads tokens with operator>> and never leaves its loop once the stream has
// failed (a non-numeric count or version is enough).
PlyHeader parse_ply_header(const std::string& path, const std::string& data) {
  PlyHeader h;
  LineReader lines{data.data(), data.data() + std::min<size_t>(data.size(), 1 << 20)};
  std::string_view raw;
  auto bad = [&](const std::string& what) {
    return InputError(error_line(path, "PLY header line " + std::to_string(lines.line) + ": " + what));
  };
  while (lines.next(raw)) {
    std::string line(raw);
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (lines.line == 1) {
      if (line != "ply" && line != "PLY") throw InputError(error_line(path, "not a PLY file (first line is not 'ply')"));
      continue;
    }
    for (char ch : line)
      if (static_cast<unsigned char>(ch) < 32 && ch != '\t') throw bad("control character in the header");
    std::istringstream ls(line);
    std::vector<std::string> tok;
    for (std::string t; ls >> t;) tok.push_back(t);
    if (tok.empty()) throw bad("empty line");
    const std::string& kw = tok[0];
    if (lines.line == 2) {
      if (tok.size() != 3 || kw != "format" || tok[2] != "1.0") throw bad("expected 'format <ascii|binary_little_endian|binary_big_endian> 1.0'");
      if (tok[1] == "ascii") h.format = PlyHeader::Ascii;
      else if (tok[1] == "binary_little_endian") h.format = PlyHeader::BinaryLE;
      else if (tok[1] == "binary_big_endian") h.format = PlyHeader::BinaryBE;
      else throw bad("unknown format '" + tok[1].substr(0, 40) + "'");
      continue;
    }
    if (kw == "end_header") {
      if (tok.size() != 1) throw bad("text after end_header");
      h.body = static_cast<size_t>(lines.p - data.data());
      return h;
    }
    if (kw == "comment") continue;
    if (kw == "obj_info") {
      // OpenMesh reads these word by word as unknown keywords: harmless unless a word is a keyword.
      for (size_t i = 1; i < tok.size(); ++i)
        if (tok[i] == "element" || tok[i] == "property" || tok[i] == "comment" || tok[i] == "end_header")
          throw bad("obj_info line contains the keyword '" + tok[i] + "'");
      continue;
    }
    if (kw == "element") {
      if (tok.size() != 3 || !is_ply_name(tok[1]) || tok[2].empty() ||
          tok[2].find_first_not_of("0123456789") != std::string::npos || tok[2].size() > 10 ||
          std::stoull(tok[2]) > 0xFFFFFFFFull)
        throw bad("malformed element declaration (expected 'element <name> <count>')");
      h.elements.push_back({tok[1], std::stoull(tok[2]), {}});
      continue;
    }
    if (kw == "property") {
      if (h.elements.empty()) throw bad("property before any element");
      PlyProperty prop;
      if (tok.size() == 3 && ply_type(tok[1], prop.type) && is_ply_name(tok[2])) {
        prop.name = tok[2];
      } else if (tok.size() == 5 && tok[1] == "list" && ply_type(tok[2], prop.count_type) &&
                 ply_type(tok[3], prop.type) && is_ply_name(tok[4])) {
        prop.list = true;
        prop.name = tok[4];
        if (prop.count_type == PlyType::Float32 || prop.count_type == PlyType::Float64)
          throw bad("list count type must be an integer type");
      } else {
        throw bad("malformed property declaration");
      }
      h.elements.back().props.push_back(prop);
      continue;
    }
    throw bad("unknown keyword '" + kw.substr(0, 40) + "'");
  }
  throw InputError(error_line(path, "PLY header has no 'end_header' line (truncated or not a PLY file)"));
}

// Reads the values of the body in declaration order, whatever the encoding.
class PlyValues {
 public:
  PlyValues(const std::string& path, const std::string& data, const PlyHeader& h)
      : path_(path), p_(data.data() + h.body), end_(data.data() + data.size()), format_(h.format) {}

  double next(PlyType t, const char* what) {
    if (format_ == PlyHeader::Ascii) return next_ascii(t, what);
    const size_t n = ply_size(t);
    if (static_cast<size_t>(end_ - p_) < n)
      throw InputError(error_line(path_, std::string("file ends inside ") + what + " (truncated?)"));
    unsigned char b[8];
    std::memcpy(b, p_, n);
    p_ += n;
    if (format_ == PlyHeader::BinaryBE) std::reverse(b, b + n);  // the hosts we build for are little-endian
    switch (t) {
      case PlyType::Int8: return static_cast<int8_t>(b[0]);
      case PlyType::UInt8: return b[0];
      case PlyType::Int16: { int16_t v; std::memcpy(&v, b, 2); return v; }
      case PlyType::UInt16: { uint16_t v; std::memcpy(&v, b, 2); return v; }
      case PlyType::Int32: { int32_t v; std::memcpy(&v, b, 4); return v; }
      case PlyType::UInt32: { uint32_t v; std::memcpy(&v, b, 4); return v; }
      case PlyType::Float32: { float v; std::memcpy(&v, b, 4); return v; }
      case PlyType::Float64: { double v; std::memcpy(&v, b, 8); return v; }
    }
    return 0;
  }
  size_t remaining() const { return static_cast<size_t>(end_ - p_); }

 private:
  double next_ascii(PlyType t, const char* what) {
    while (p_ < end_ && (is_blank(*p_) || *p_ == '\n')) ++p_;
    if (p_ >= end_) throw InputError(error_line(path_, std::string("file ends inside ") + what + " (truncated?)"));
    const char* b = p_;
    while (p_ < end_ && !is_blank(*p_) && *p_ != '\n') ++p_;
    const std::string_view tok(b, static_cast<size_t>(p_ - b));
    if (t == PlyType::Float32 || t == PlyType::Float64) {
      float f;
      if (!parse_float(tok, f))
        throw InputError(error_line(path_, std::string(what) + ": " + quote(tok) + " is not a number"));
      return f;
    }
    long long v;
    if (!parse_int_prefix(tok, v, nullptr))
      throw InputError(error_line(path_, std::string(what) + ": " + quote(tok) + " is not an integer"));
    return static_cast<double>(v);
  }

  const std::string& path_;
  const char* p_;
  const char* end_;
  PlyHeader::Format format_;
};

Scene parse_ply(const std::string& path, const std::string& data) {
  const PlyHeader h = parse_ply_header(path, data);
  const PlyElement* ve = h.find("vertex");
  const PlyElement* fe = h.find("face");
  if (!ve) throw InputError(error_line(path, "PLY file declares no 'vertex' element"));
  if (!fe || fe->count == 0)
    throw InputError(error_line(path, "PLY file declares no faces (only the 'face' element is read; "
                                      "'tristrips' and point clouds are not supported)"));
  int ix = -1, iy = -1, iz = -1, iface = -1;
  for (size_t i = 0; i < ve->props.size(); ++i) {
    const auto& pr = ve->props[i];
    if (pr.list) continue;
    if (pr.name == "x") ix = static_cast<int>(i);
    if (pr.name == "y") iy = static_cast<int>(i);
    if (pr.name == "z") iz = static_cast<int>(i);
  }
  if (ix < 0 || iy < 0 || iz < 0) throw InputError(error_line(path, "PLY vertex element lacks an x, y or z property"));
  for (size_t i = 0; i < fe->props.size(); ++i)
    if (fe->props[i].list && (fe->props[i].name == "vertex_indices" || fe->props[i].name == "vertex_index"))
      iface = static_cast<int>(i);
  if (iface < 0) throw InputError(error_line(path, "PLY face element lacks a vertex_indices list"));
  if (ve->count >= kMaxElements) throw InputError(error_line(path, "more than 2^32-2 vertices"));

  // Each element item takes at least one byte (binary) or two (ASCII value + separator); larger
  // counts are a wrong header or a cut file and must not become huge reservations.
  const size_t body = data.size() - h.body;
  for (const auto& e : h.elements)
    if (!e.props.empty() && e.count > body)
      throw InputError(error_line(path, "header declares " + std::to_string(e.count) + " '" + e.name +
                                            "' elements, more than the " + std::to_string(body) +
                                            "-byte body can hold (truncated?)"));

  Scene s;
  s.name = detail::file_stem(path);
  s.positions.reserve(ve->count);
  s.triangles.reserve(fe->count);
  PlyValues in(path, data, h);
  std::vector<uint32_t> face;
  for (const PlyElement& e : h.elements) {
    const bool is_v = &e == ve, is_f = &e == fe;
    if (e.props.empty()) continue;  // no bytes to read: skip, rather than count to 2^32 for nothing
    for (uint64_t item = 0; item < e.count; ++item) {
      Vec3 p;
      for (size_t pi = 0; pi < e.props.size(); ++pi) {
        const PlyProperty& pr = e.props[pi];
        if (!pr.list) {
          const double v = in.next(pr.type, is_v ? "a vertex" : (is_f ? "a face" : "an element"));
          if (is_v) {
            if (static_cast<int>(pi) == ix) p.x = static_cast<float>(v);
            if (static_cast<int>(pi) == iy) p.y = static_cast<float>(v);
            if (static_cast<int>(pi) == iz) p.z = static_cast<float>(v);
          }
          continue;
        }
        const double count = in.next(pr.count_type, "a list length");
        if (count < 0 || count > static_cast<double>(in.remaining()))
          throw InputError(error_line(path, e.name + " " + std::to_string(item) + ": list length " +
                                                std::to_string(static_cast<long long>(count)) +
                                                " is negative or longer than the rest of the file"));
        const size_t n = static_cast<size_t>(count);
        const bool indices = is_f && static_cast<int>(pi) == iface;
        if (indices) face.clear();
        for (size_t k = 0; k < n; ++k) {
          const double v = in.next(pr.type, indices ? "a face" : "a list");
          if (!indices) continue;
          if (!(v >= 0 && v < static_cast<double>(ve->count)) || v != std::floor(v)) {
            // A float-typed index list can hold anything (NaN, 1e300): print it as a number, since
            // converting such a value to an integer is undefined behaviour.
            char shown[32];
            std::snprintf(shown, sizeof shown, "%.17g", v);
            throw InputError(error_line(path, "face " + std::to_string(item) + " uses vertex index " + shown +
                                                  (v == std::floor(v) ? " but there are " + std::to_string(ve->count) +
                                                                            " vertices"
                                                                      : std::string(", not an integer"))));
          }
          face.push_back(static_cast<uint32_t>(v));
        }
        if (indices) {
          if (face.size() < 3)
            throw InputError(error_line(path, "face " + std::to_string(item) + " has " + std::to_string(face.size()) +
                                                  " vertices, needs at least 3"));
          for (size_t i = 2; i < face.size(); ++i) s.triangles.push_back({face[0], face[i - 1], face[i]});
          if (s.triangles.size() > kMaxElements) throw InputError(error_line(path, "more than 2^32-2 triangles"));
        }
      }
      if (is_v) {
        if (!is_finite(p))
          throw InputError(error_line(path, "vertex " + std::to_string(item) + " has a NaN or Inf coordinate"));
        s.positions.push_back(p);
      }
    }
  }
  // Anything after the last element carries no geometry: padding of a binary body is ignored, but
  // values left in an ASCII body mean the header's counts are wrong (more faces than declared, or
  // extra values on a face line that shifted every later face) and the file was read wrongly.
  if (h.format == PlyHeader::Ascii && in.remaining() > 0) {
    const char* rest = data.data() + (data.size() - in.remaining());
    for (const char* q = rest; q < data.data() + data.size(); ++q)
      if (!is_blank(*q) && *q != '\n' && *q != '\r')
        throw InputError(error_line(path, "values after the " + std::to_string(h.elements.back().count) + " '" +
                                              h.elements.back().name +
                                              "' elements the header declares (wrong counts, or extra values on a line)"));
  }
  return s;
}

// ---------------------------------------------------------------------------------------------
// OpenMesh: the second reading (load_mesh_openmesh)

// Receives what an OpenMesh reader parses and keeps it as a triangle soup in reading order:
// polygons are fanned (v0, v{i-1}, v{i}) like everything else; no connectivity is built, so the
// "complex edge" rejections and vertex duplication of OpenMesh's mesh importer never happen.
class SoupImporter final : public OpenMesh::IO::BaseImporter {
 public:
  using VertexHandle = OpenMesh::VertexHandle;
  using FaceHandle = OpenMesh::FaceHandle;
  using HalfedgeHandle = OpenMesh::HalfedgeHandle;
  using EdgeHandle = OpenMesh::EdgeHandle;
  using Vec3f = OpenMesh::Vec3f;
  using Vec3d = OpenMesh::Vec3d;

  // Thrown out of the reader when it produces more elements than the file declares or can hold, so
  // that a reader misled by a corrupt file stops instead of growing the scene without bound.
  struct TooMuch {};

  Scene& scene;
  size_t polygons = 0;
  size_t max_vertices, max_polygons;
  std::string error;  // first problem seen; readers keep going, so the loader reports it afterwards

  SoupImporter(Scene& s, size_t max_v, size_t max_p) : scene(s), max_vertices(max_v), max_polygons(max_p) {}

  VertexHandle add_vertex(const Vec3f& p) override {
    if (scene.positions.size() >= max_vertices) throw TooMuch{};
    scene.positions.push_back({p[0], p[1], p[2]});
    return VertexHandle(static_cast<int>(scene.positions.size() - 1));
  }
  VertexHandle add_vertex(const Vec3d& p) override { return add_vertex(Vec3f(float(p[0]), float(p[1]), float(p[2]))); }
  VertexHandle add_vertex() override { return add_vertex(Vec3f(0.f, 0.f, 0.f)); }
  void set_point(VertexHandle vh, const Vec3f& p) override {
    if (vh.idx() >= 0 && static_cast<size_t>(vh.idx()) < scene.positions.size())
      scene.positions[static_cast<size_t>(vh.idx())] = {p[0], p[1], p[2]};
  }
  FaceHandle add_face(const VHandles& v) override {
    if (polygons >= max_polygons) throw TooMuch{};
    const size_t poly = polygons++;
    if (v.size() < 3) {
      note("face " + std::to_string(poly) + " has " + std::to_string(v.size()) + " vertices, needs at least 3");
      return FaceHandle();
    }
    for (const VertexHandle& h : v)
      if (h.idx() < 0 || static_cast<size_t>(h.idx()) >= scene.positions.size()) {
        note("face " + std::to_string(poly) + " uses vertex index " + std::to_string(h.idx()) + " but there are " +
             std::to_string(scene.positions.size()) + " vertices");
        return FaceHandle();
      }
    for (size_t i = 2; i < v.size(); ++i)
      scene.triangles.push_back({uint32_t(v[0].idx()), uint32_t(v[i - 1].idx()), uint32_t(v[i].idx())});
    return FaceHandle(static_cast<int>(scene.triangles.size() - 1));
  }
  // Only the OM format builds faces from halfedges; it is not a scene format here.
  HalfedgeHandle add_edge(VertexHandle, VertexHandle) override {
    note("half-edge based input is not supported");
    return HalfedgeHandle();
  }
  FaceHandle add_face(HalfedgeHandle) override {
    note("half-edge based input is not supported");
    return FaceHandle();
  }
  size_t n_vertices() const override { return scene.positions.size(); }
  size_t n_faces() const override { return scene.triangles.size(); }
  size_t n_edges() const override { return 0; }

  // Attributes: not needed for traversal.
  void add_face_texcoords(FaceHandle, VertexHandle, const std::vector<OpenMesh::Vec2f>&) override {}
  void add_face_texcoords(FaceHandle, VertexHandle, const std::vector<Vec3f>&) override {}
  void set_face_texindex(FaceHandle, int) override {}
  void set_halfedge(VertexHandle, HalfedgeHandle) override {}
  void set_normal(VertexHandle, const Vec3f&) override {}
  void set_normal(VertexHandle, const Vec3d&) override {}
  void set_color(VertexHandle, const OpenMesh::Vec3uc&) override {}
  void set_color(VertexHandle, const OpenMesh::Vec4uc&) override {}
  void set_color(VertexHandle, const Vec3f&) override {}
  void set_color(VertexHandle, const OpenMesh::Vec4f&) override {}
  void set_texcoord(VertexHandle, const OpenMesh::Vec2f&) override {}
  void set_status(VertexHandle, const OpenMesh::Attributes::StatusInfo&) override {}
  void set_next(HalfedgeHandle, HalfedgeHandle) override {}
  void set_face(HalfedgeHandle, FaceHandle) override {}
  void request_face_texcoords2D() override {}
  void set_texcoord(HalfedgeHandle, const OpenMesh::Vec2f&) override {}
  void set_texcoord(VertexHandle, const Vec3f&) override {}
  void set_texcoord(HalfedgeHandle, const Vec3f&) override {}
  void set_status(HalfedgeHandle, const OpenMesh::Attributes::StatusInfo&) override {}
  void set_color(EdgeHandle, const OpenMesh::Vec3uc&) override {}
  void set_color(EdgeHandle, const OpenMesh::Vec4uc&) override {}
  void set_color(EdgeHandle, const Vec3f&) override {}
  void set_color(EdgeHandle, const OpenMesh::Vec4f&) override {}
  void set_status(EdgeHandle, const OpenMesh::Attributes::StatusInfo&) override {}
  void set_normal(FaceHandle, const Vec3f&) override {}
  void set_normal(FaceHandle, const Vec3d&) override {}
  void set_color(FaceHandle, const OpenMesh::Vec3uc&) override {}
  void set_color(FaceHandle, const OpenMesh::Vec4uc&) override {}
  void set_color(FaceHandle, const Vec3f&) override {}
  void set_color(FaceHandle, const OpenMesh::Vec4f&) override {}
  void set_status(FaceHandle, const OpenMesh::Attributes::StatusInfo&) override {}
  void add_texture_information(int, std::string) override {}

 private:
  void note(const std::string& what) {
    if (error.empty()) error = what;
  }
};

// OpenMesh reports problems by printing to its global omerr/omlog/omout streams ("complex edge",
// "Unsupported keyword", ...); our checks report them as InputError instead, so the streams are
// muted while a file is read. (Redirecting them into a buffer would need mostream::disconnect,
// which leaks its target object on every call.) The streams are process-wide, hence the mutex.
class OmSilence {
 public:
  OmSilence() : lock_(mutex()) {
    for (OpenMesh::mostream* s : {&omerr(), &omlog(), &omout()}) {
      s->flush();
      saved_.push_back({s, s->is_enabled()});
      s->disable();
    }
  }
  ~OmSilence() {
    for (const auto& [stream, enabled] : saved_) {
      stream->flush();  // drops what was buffered while muted
      if (enabled) stream->enable();
    }
  }

 private:
  static std::mutex& mutex() {
    static std::mutex m;
    return m;
  }
  std::lock_guard<std::mutex> lock_;
  std::vector<std::pair<OpenMesh::mostream*, bool>> saved_;
};

}  // namespace

Scene load_obj(const std::string& path) { return parse_obj(path, detail::read_file_bytes(path)); }
Scene load_off(const std::string& path) { return parse_off(path, detail::read_file_bytes(path)); }
Scene load_stl(const std::string& path) { return parse_stl(path, detail::read_file_bytes(path)); }
Scene load_ply(const std::string& path) { return parse_ply(path, detail::read_file_bytes(path)); }

Scene load_mesh_openmesh(const std::string& path) {
  detail::check_regular_file(path);
  std::string ext = std::filesystem::path(path).extension().string();
  if (!ext.empty()) ext.erase(0, 1);
  for (char& ch : ext) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  // (IOManager::can_read is no help here: for PLY/OFF/OM it probes a dummy file name and says no.)
  static const char* const kOpenMeshExtensions[] = {"obj", "off", "om", "ply", "stl", "stla", "stlb"};
  if (std::find(std::begin(kOpenMeshExtensions), std::end(kOpenMeshExtensions), ext) == std::end(kOpenMeshExtensions))
    throw InputError(error_line(path, "OpenMesh has no reader for extension '" + ext + "'"));

  const bool is_ply = ext == "ply";
  long long declared_vertices = -1, declared_faces = -1;
  if (is_ply) {
    // OpenMesh's PLY reader must only see headers it is sure to parse (see parse_ply_header), and
    // its element counts are what the reader's output is checked against.
    const PlyHeader h = parse_ply_header(path, detail::read_file_bytes(path));
    const PlyElement* ve = h.find("vertex");
    const PlyElement* fe = h.find("face");
    if (!ve) throw InputError(error_line(path, "PLY file declares no 'vertex' element"));
    if (!fe || fe->count == 0) throw InputError(error_line(path, "PLY file declares no faces"));
    declared_vertices = static_cast<long long>(ve->count);
    declared_faces = static_cast<long long>(fe->count);
    // Every element needs at least one byte; larger counts must not reach OpenMesh's allocations.
    const auto size = static_cast<long long>(std::filesystem::file_size(path));
    if (declared_vertices + declared_faces > size)
      throw InputError(error_line(path, "PLY header declares " + std::to_string(declared_vertices) + " vertices and " +
                                            std::to_string(declared_faces) + " faces, more than a " +
                                            std::to_string(size) + "-byte file can hold (truncated?)"));
  }

  Scene s;
  s.name = detail::file_stem(path);
  // Limits: the PLY header's counts; otherwise one element per byte of file, which no real file of
  // these formats reaches.
  const auto file_bytes = static_cast<size_t>(std::filesystem::file_size(path));
  SoupImporter importer(s, is_ply ? static_cast<size_t>(declared_vertices) : file_bytes,
                        is_ply ? static_cast<size_t>(declared_faces) : file_bytes);
  OpenMesh::IO::Options opt;
  bool ok = false;
  bool stream_failed = false;
  {
    OmSilence silence;
    try {
      if (is_ply) {
        // The stream overload lets us see whether the reader ran out of data (failbit): OpenMesh's
        // PLY reader itself fills missing elements with stale values and reports success.
        std::ifstream in(path, std::ios::binary);
        ok = OpenMesh::IO::IOManager().read(in, ext, importer, opt);
        stream_failed = in.fail();
      } else {
        ok = OpenMesh::IO::IOManager().read(path, importer, opt);
      }
    } catch (const SoupImporter::TooMuch&) {
      throw InputError(error_line(path, "OpenMesh's reader produced more vertices or faces than the " +
                                            std::string(is_ply ? "header declares" : "file can hold") + " (corrupt file?)"));
    } catch (const std::exception& e) {
      throw InputError(error_line(path, std::string("OpenMesh failed to read the file (") + e.what() + ")"));
    }
  }
  // A failed stream explains everything after it (OpenMesh keeps "reading" stale values), so it is
  // reported first.
  if (stream_failed)
    throw InputError(error_line(path, "file ends early or holds a value that is not a number (truncated?)"));
  if (!ok) throw InputError(error_line(path, "OpenMesh could not read the file"));
  if (!importer.error.empty()) throw InputError(error_line(path, importer.error));
  if (is_ply) {
    if (static_cast<long long>(s.positions.size()) != declared_vertices ||
        static_cast<long long>(importer.polygons) != declared_faces)
      throw InputError(error_line(path, "header declares " + std::to_string(declared_vertices) + " vertices and " +
                                            std::to_string(declared_faces) + " faces but OpenMesh read " +
                                            std::to_string(s.positions.size()) + " and " +
                                            std::to_string(importer.polygons)));
  }
  for (size_t i = 0; i < s.positions.size(); ++i)
    if (!is_finite(s.positions[i]))
      throw InputError(error_line(path, "vertex " + std::to_string(i) + " has a NaN or Inf coordinate"));
  if (s.triangles.size() > kMaxElements || s.positions.size() > kMaxElements)
    throw InputError(error_line(path, "more than 2^32-2 triangles or vertices"));
  return s;
}

}  // namespace tb
