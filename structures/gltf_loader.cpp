// glTF 2.0 (.gltf and .glb) through Debian's compiled tinygltf 2.7 (libtinygltf.so).
//
// The header is used as the library was built: no TINYGLTF_IMPLEMENTATION (the code lives in the
// .so) and no TINYGLTF_NO_* macros — those only change which default callbacks the inline TinyGLTF
// members point at, and the library exports the stb-based ones. Image decoding is switched off at
// run time instead (skip_image below): traversal needs no textures, and decoding them would cost time
// and turn a broken texture into a failed scene.
//
// tinygltf parses JSON, GLB chunks and buffers (data URIs, external .bin files); everything that
// turns them into triangles is checked here, because tinygltf 2.7 does not bound-check accessors
// against their buffer views or indices against vertex counts.
//
// Triangle order (= primitive ids): the scene's root nodes in order, each node before its children
// (depth first, children in order), each node's mesh primitives in order, and within a primitive the
// glTF triangle order (strips and fans converted by the spec's formulas). Each node instance appends
// its own transformed copy of the primitive's vertices.
#include <tiny_gltf.h>

#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <numbers>
#include <type_traits>

#include "structures/scene_loader.h"

namespace tb {

namespace {

using detail::error_line;
using Mat4 = std::array<double, 16>;  // column-major, as glTF stores node.matrix

constexpr size_t kMaxElements = 0xFFFFFFFEull;  // uint32 primitive ids, 0xFFFFFFFF = no hit

Mat4 identity() {
  Mat4 m{};
  m[0] = m[5] = m[10] = m[15] = 1.0;
  return m;
}

Mat4 mul(const Mat4& a, const Mat4& b) {
  Mat4 r{};
  for (int c = 0; c < 4; ++c)
    for (int row = 0; row < 4; ++row) {
      double s = 0;
      for (int k = 0; k < 4; ++k) s += a[k * 4 + row] * b[c * 4 + k];
      r[c * 4 + row] = s;
    }
  return r;
}

bool all_finite(const std::vector<double>& v) {
  for (double x : v)
    if (!std::isfinite(x)) return false;
  return true;
}

// Node-local transform: matrix if given, else T * R * S (glTF 2.0 §5.25).
Mat4 local_matrix(const tinygltf::Node& n, const std::string& path, size_t idx) {
  const std::string where = "node " + std::to_string(idx) + ": ";
  if (!all_finite(n.matrix) || !all_finite(n.translation) || !all_finite(n.rotation) || !all_finite(n.scale))
    throw InputError(error_line(path, where + "transform has a NaN or Inf value"));
  if (!n.matrix.empty()) {
    if (n.matrix.size() != 16) throw InputError(error_line(path, where + "matrix must have 16 numbers"));
    Mat4 m;
    std::copy(n.matrix.begin(), n.matrix.end(), m.begin());
    return m;
  }
  if (!n.translation.empty() && n.translation.size() != 3)
    throw InputError(error_line(path, where + "translation must have 3 numbers"));
  if (!n.rotation.empty() && n.rotation.size() != 4)
    throw InputError(error_line(path, where + "rotation must be a quaternion of 4 numbers"));
  if (!n.scale.empty() && n.scale.size() != 3) throw InputError(error_line(path, where + "scale must have 3 numbers"));
  double t[3] = {0, 0, 0}, q[4] = {0, 0, 0, 1}, s[3] = {1, 1, 1};
  for (int i = 0; i < 3 && !n.translation.empty(); ++i) t[i] = n.translation[i];
  for (int i = 0; i < 4 && !n.rotation.empty(); ++i) q[i] = n.rotation[i];
  for (int i = 0; i < 3 && !n.scale.empty(); ++i) s[i] = n.scale[i];
  // The spec requires unit quaternions; exporters round, so normalise rather than skew the mesh.
  const double qn = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  if (!(qn > 0)) throw InputError(error_line(path, where + "rotation quaternion is zero"));
  const double x = q[0] / qn, y = q[1] / qn, z = q[2] / qn, w = q[3] / qn;
  const double r[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)},
                          {2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)},
                          {2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)}};
  Mat4 m{};
  for (int c = 0; c < 3; ++c)
    for (int row = 0; row < 3; ++row) m[c * 4 + row] = r[row][c] * s[c];
  m[12] = t[0];
  m[13] = t[1];
  m[14] = t[2];
  m[15] = 1;
  return m;
}

int component_size(int type) {
  switch (type) {
    case TINYGLTF_COMPONENT_TYPE_BYTE:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return 1;
    case TINYGLTF_COMPONENT_TYPE_SHORT:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: return 2;
    case TINYGLTF_COMPONENT_TYPE_INT:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
    case TINYGLTF_COMPONENT_TYPE_FLOAT: return 4;
    case TINYGLTF_COMPONENT_TYPE_DOUBLE: return 8;
    default: return 0;
  }
}

int component_count(int type) {
  switch (type) {
    case TINYGLTF_TYPE_SCALAR: return 1;
    case TINYGLTF_TYPE_VEC2: return 2;
    case TINYGLTF_TYPE_VEC3: return 3;
    case TINYGLTF_TYPE_VEC4: return 4;
    case TINYGLTF_TYPE_MAT2: return 4;
    case TINYGLTF_TYPE_MAT3: return 9;
    case TINYGLTF_TYPE_MAT4: return 16;
    default: return 0;
  }
}

// An accessor resolved to bytes, with every element proven to lie inside its buffer.
struct Elements {
  const unsigned char* data = nullptr;  // null: no bufferView, every element is zero (spec §5.1.2)
  size_t stride = 0;
  size_t count = 0;
  int component = 0;
  bool normalized = false;
  std::shared_ptr<std::vector<unsigned char>> owned;  // a sparse accessor's elements, made dense
};

// `bytes` bytes at `offset` into buffer view `view`, proven to lie inside it and its buffer.
const unsigned char* view_bytes(const tinygltf::Model& m, int view, size_t offset, size_t bytes, const std::string& path,
                                const std::string& wa) {
  if (view < 0 || static_cast<size_t>(view) >= m.bufferViews.size())
    throw InputError(error_line(path, wa + "bufferView " + std::to_string(view) + " does not exist"));
  const tinygltf::BufferView& bv = m.bufferViews[static_cast<size_t>(view)];
  if (bv.buffer < 0 || static_cast<size_t>(bv.buffer) >= m.buffers.size())
    throw InputError(error_line(path, wa + "bufferView " + std::to_string(view) + " names buffer " +
                                          std::to_string(bv.buffer) + ", which does not exist"));
  const tinygltf::Buffer& buf = m.buffers[static_cast<size_t>(bv.buffer)];
  if (bv.byteOffset > buf.data.size() || bv.byteLength > buf.data.size() - bv.byteOffset || offset > bv.byteLength ||
      bytes > bv.byteLength - offset)
    throw InputError(error_line(path, wa + std::to_string(bytes) + " bytes at offset " + std::to_string(offset) +
                                          " do not fit in bufferView " + std::to_string(view)));
  return buf.data.data() + bv.byteOffset + offset;
}

// implicit_limit: the most elements an accessor without bufferView (all zeros, spec §3.6.2.3) may
// declare. Nothing backs such a count, so without a bound a one-line header could ask for gigabytes.
Elements resolve_dense(const tinygltf::Model& m, const tinygltf::Accessor& a, const std::string& path,
                       const std::string& wa, size_t implicit_limit) {
  const int csize = component_size(a.componentType);
  const int ncomp = component_count(a.type);
  if (csize == 0 || ncomp == 0) throw InputError(error_line(path, wa + "invalid componentType or type"));
  Elements e;
  e.count = a.count;
  e.component = a.componentType;
  e.normalized = a.normalized;
  if (a.bufferView < 0) {
    if (e.count > implicit_limit)
      throw InputError(error_line(path, wa + "has no bufferView but declares " + std::to_string(e.count) +
                                            " elements, more than a " + std::to_string(implicit_limit) +
                                            "-byte file describes"));
    return e;
  }
  if (static_cast<size_t>(a.bufferView) >= m.bufferViews.size())
    throw InputError(error_line(path, wa + "bufferView " + std::to_string(a.bufferView) + " does not exist"));
  const tinygltf::BufferView& bv = m.bufferViews[static_cast<size_t>(a.bufferView)];
  if (bv.buffer < 0 || static_cast<size_t>(bv.buffer) >= m.buffers.size())
    throw InputError(error_line(path, wa + "bufferView " + std::to_string(a.bufferView) + " names buffer " +
                                          std::to_string(bv.buffer) + ", which does not exist"));
  const tinygltf::Buffer& buf = m.buffers[static_cast<size_t>(bv.buffer)];
  if (bv.byteOffset > buf.data.size() || bv.byteLength > buf.data.size() - bv.byteOffset)
    throw InputError(error_line(path, wa + "bufferView " + std::to_string(a.bufferView) + " (bytes " +
                                          std::to_string(bv.byteOffset) + "+" + std::to_string(bv.byteLength) +
                                          ") runs past the end of buffer " + std::to_string(bv.buffer) + " (" +
                                          std::to_string(buf.data.size()) + " bytes)"));
  const size_t elem = static_cast<size_t>(csize) * static_cast<size_t>(ncomp);
  e.stride = bv.byteStride ? bv.byteStride : elem;
  if (e.stride < elem)
    throw InputError(error_line(path, wa + "byteStride " + std::to_string(bv.byteStride) + " is smaller than an element (" +
                                          std::to_string(elem) + " bytes)"));
  if (e.count > 0) {
    // offset + (count-1)*stride + elem <= byteLength, written so that nothing can overflow.
    const size_t avail = bv.byteLength;
    const bool fits = a.byteOffset <= avail && elem <= avail - a.byteOffset &&
                      (e.count - 1) <= (avail - a.byteOffset - elem) / e.stride;
    if (!fits)
      throw InputError(error_line(path, wa + std::to_string(e.count) + " elements at offset " +
                                            std::to_string(a.byteOffset) + " with stride " + std::to_string(e.stride) +
                                            " do not fit in bufferView " + std::to_string(a.bufferView) + " (" +
                                            std::to_string(avail) + " bytes)"));
  }
  e.data = buf.data.data() + bv.byteOffset + a.byteOffset;
  return e;
}

uint32_t read_index(const unsigned char* p, int type);  // below, with the other element readers

Elements resolve_accessor(const tinygltf::Model& m, int index, const std::string& path, const std::string& where,
                          size_t implicit_limit) {
  if (index < 0 || static_cast<size_t>(index) >= m.accessors.size())
    throw InputError(error_line(path, where + "accessor " + std::to_string(index) + " does not exist (" +
                                          std::to_string(m.accessors.size()) + " accessors)"));
  const tinygltf::Accessor& a = m.accessors[static_cast<size_t>(index)];
  const std::string wa = where + "accessor " + std::to_string(index) + ": ";
  Elements e = resolve_dense(m, a, path, wa, implicit_limit);
  if (!a.sparse.isSparse) return e;
  // Sparse (glTF 2.0 §3.6.2.4): the base elements (its bufferView, or zeros) with `count` of them
  // replaced; made dense here, so the readers below see one layout.
  const size_t elem = static_cast<size_t>(component_size(a.componentType)) * static_cast<size_t>(component_count(a.type));
  if (a.sparse.count < 1 || static_cast<size_t>(a.sparse.count) > e.count)
    throw InputError(error_line(path, wa + "sparse count " + std::to_string(a.sparse.count) + " is not in 1.." +
                                          std::to_string(e.count)));
  const int itype = a.sparse.indices.componentType;
  if (itype != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE && itype != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
      itype != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)
    throw InputError(error_line(path, wa + "sparse indices must be unsigned byte/short/int"));
  const size_t n = static_cast<size_t>(a.sparse.count), isize = static_cast<size_t>(component_size(itype));
  if (a.sparse.indices.byteOffset < 0 || a.sparse.values.byteOffset < 0)
    throw InputError(error_line(path, wa + "sparse byteOffset is negative"));
  const unsigned char* ip = view_bytes(m, a.sparse.indices.bufferView, static_cast<size_t>(a.sparse.indices.byteOffset),
                                       n * isize, path, wa + "sparse indices: ");
  const unsigned char* vp = view_bytes(m, a.sparse.values.bufferView, static_cast<size_t>(a.sparse.values.byteOffset),
                                       n * elem, path, wa + "sparse values: ");
  e.owned = std::make_shared<std::vector<unsigned char>>(e.count * elem, 0);
  if (e.data)
    for (size_t i = 0; i < e.count; ++i) std::memcpy(e.owned->data() + i * elem, e.data + i * e.stride, elem);
  for (size_t k = 0; k < n; ++k) {
    const uint32_t i = read_index(ip + k * isize, itype);
    if (i >= e.count)
      throw InputError(error_line(path, wa + "sparse index " + std::to_string(i) + " is out of range for " +
                                            std::to_string(e.count) + " elements"));
    std::memcpy(e.owned->data() + size_t(i) * elem, vp + k * elem, elem);
  }
  e.data = e.owned->data();
  e.stride = elem;
  return e;
}

template <class T>
T load_unaligned(const unsigned char* p) {
  T v;
  std::memcpy(&v, p, sizeof v);  // glTF data is little-endian, like every target we build for
  return v;
}

// An integer component; normalised, it maps to [0,1] (unsigned) or [-1,1] (signed: the spec divides
// by the largest value and clamps the one below -1, e.g. -128 / 127).
template <class T>
double read_integer(const unsigned char* p, bool normalized) {
  const double v = load_unaligned<T>(p);
  if (!normalized) return v;
  const double scaled = v / std::numeric_limits<T>::max();
  return std::is_signed_v<T> ? std::max(scaled, -1.0) : scaled;
}

// One component as a number; normalised integers map to [0,1] / [-1,1] (KHR_mesh_quantization).
double read_component(const unsigned char* p, int type, bool normalized) {
  switch (type) {
    case TINYGLTF_COMPONENT_TYPE_FLOAT: return load_unaligned<float>(p);
    case TINYGLTF_COMPONENT_TYPE_BYTE: return read_integer<int8_t>(p, normalized);
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return read_integer<uint8_t>(p, normalized);
    case TINYGLTF_COMPONENT_TYPE_SHORT: return read_integer<int16_t>(p, normalized);
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: return read_integer<uint16_t>(p, normalized);
    default: return 0;  // rejected before reading
  }
}

uint32_t read_index(const unsigned char* p, int type) {
  switch (type) {
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return load_unaligned<uint8_t>(p);
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: return load_unaligned<uint16_t>(p);
    default: return load_unaligned<uint32_t>(p);
  }
}

class Builder {
 public:
  Builder(const tinygltf::Model& m, const std::string& path, Scene& s, size_t implicit_limit)
      : m_(m), path_(path), s_(s), implicit_limit_(implicit_limit) {}

  void add_mesh(int mesh_index, const Mat4& world, const std::string& via) {
    if (mesh_index < 0 || static_cast<size_t>(mesh_index) >= m_.meshes.size())
      throw InputError(error_line(path_, via + "mesh " + std::to_string(mesh_index) + " does not exist (" +
                                             std::to_string(m_.meshes.size()) + " meshes)"));
    const tinygltf::Mesh& mesh = m_.meshes[static_cast<size_t>(mesh_index)];
    for (size_t p = 0; p < mesh.primitives.size(); ++p)
      add_primitive(mesh.primitives[p], world, "mesh " + std::to_string(mesh_index) + " primitive " + std::to_string(p) + ": ");
  }

 private:
  void add_primitive(const tinygltf::Primitive& prim, const Mat4& world, const std::string& where) {
    const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
    // Points and lines have no surface a ray can hit. Skipping them would trace a scene other than
    // the one a viewer shows (points and lines are drawn there), as skipping a Draco primitive would
    // drop geometry, so they are refused the same way, naming the primitive (issue 20).
    if (mode == TINYGLTF_MODE_POINTS || mode == TINYGLTF_MODE_LINE || mode == TINYGLTF_MODE_LINE_LOOP ||
        mode == TINYGLTF_MODE_LINE_STRIP) {
      static const char* const kNames[] = {"POINTS", "LINES", "LINE_LOOP", "LINE_STRIP"};
      throw InputError(error_line(path_, where + "is mode " + std::to_string(mode) + " (" + kNames[mode] +
                                             "), which has no surface to trace; this loader reads triangle "
                                             "primitives only (modes 4-6: remove the point/line primitives)"));
    }
    if (mode != TINYGLTF_MODE_TRIANGLES && mode != TINYGLTF_MODE_TRIANGLE_STRIP && mode != TINYGLTF_MODE_TRIANGLE_FAN)
      throw InputError(error_line(path_, where + "unknown primitive mode " + std::to_string(mode)));
    auto pos_it = prim.attributes.find("POSITION");
    if (pos_it == prim.attributes.end()) {
      // A Draco-compressed primitive may carry no uncompressed fallback: its triangles exist, but
      // only as Draco data this loader cannot decode; skipping it would silently drop geometry.
      if (prim.extensions.count("KHR_draco_mesh_compression"))
        throw InputError(error_line(path_, where + "is Draco-compressed (KHR_draco_mesh_compression) without an "
                                                   "uncompressed POSITION; this loader does not decode Draco"));
      return;  // spec: primitives without positions are not rendered
    }

    const std::string wp = where + "POSITION ";
    Elements pos = resolve_accessor(m_, pos_it->second, path_, wp, implicit_limit_);
    const tinygltf::Accessor& pa = m_.accessors[static_cast<size_t>(pos_it->second)];
    if (pa.type != TINYGLTF_TYPE_VEC3) throw InputError(error_line(path_, wp + "accessor must be VEC3"));
    if (pa.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT && pa.componentType != TINYGLTF_COMPONENT_TYPE_BYTE &&
        pa.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE && pa.componentType != TINYGLTF_COMPONENT_TYPE_SHORT &&
        pa.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT)
      throw InputError(error_line(path_, wp + "accessor must hold floats (or 8/16-bit integers, KHR_mesh_quantization)"));
    if (pos.count == 0) return;
    if (pos.count > kMaxElements - s_.positions.size()) throw InputError(error_line(path_, "more than 2^32-2 vertices"));

    // Corner sequence of the primitive: its indices, or 0..count-1.
    std::vector<uint32_t> seq;
    if (prim.indices >= 0) {
      const std::string wi = where + "indices ";
      Elements idx = resolve_accessor(m_, prim.indices, path_, wi, implicit_limit_);
      const tinygltf::Accessor& ia = m_.accessors[static_cast<size_t>(prim.indices)];
      if (ia.type != TINYGLTF_TYPE_SCALAR ||
          (ia.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
           ia.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
           ia.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT))
        throw InputError(error_line(path_, wi + "accessor must be SCALAR unsigned byte/short/int"));
      seq.resize(idx.count);
      for (size_t i = 0; i < idx.count; ++i) {
        uint32_t v = idx.data ? read_index(idx.data + i * idx.stride, idx.component) : 0u;
        if (v >= pos.count)
          throw InputError(error_line(path_, where + "index " + std::to_string(i) + " is " + std::to_string(v) +
                                                 ", out of range for " + std::to_string(pos.count) + " vertices"));
        seq[i] = v;
      }
    } else {
      seq.resize(pos.count);
      for (size_t i = 0; i < pos.count; ++i) seq[i] = static_cast<uint32_t>(i);
    }

    const uint32_t base = static_cast<uint32_t>(s_.positions.size());
    const size_t n = seq.size();
    auto emit = [&](uint32_t a, uint32_t b, uint32_t c) {
      if (s_.triangles.size() >= kMaxElements) throw InputError(error_line(path_, "more than 2^32-2 triangles"));
      s_.triangles.push_back({base + a, base + b, base + c});
    };
    if (mode == TINYGLTF_MODE_TRIANGLES) {
      if (n % 3 != 0)
        throw InputError(error_line(path_, where + std::to_string(n) + " corners is not a multiple of 3 for TRIANGLES"));
      for (size_t i = 0; i < n; i += 3) emit(seq[i], seq[i + 1], seq[i + 2]);
    } else if (mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
      // Spec §3.7.2.1: p_i = {v_i, v_{i+(1+i%2)}, v_{i+(2-i%2)}} keeps the winding consistent.
      for (size_t i = 0; i + 2 < n; ++i) emit(seq[i], seq[i + 1 + i % 2], seq[i + 2 - i % 2]);
    } else {
      // TRIANGLE_FAN: p_i = {v_{i+1}, v_{i+2}, v_0}.
      for (size_t i = 0; i + 2 < n; ++i) emit(seq[i + 1], seq[i + 2], seq[0]);
    }

    s_.positions.reserve(s_.positions.size() + pos.count);
    const int csize = component_size(pos.component);
    for (size_t i = 0; i < pos.count; ++i) {
      double p[3] = {0, 0, 0};
      if (pos.data)
        for (int c = 0; c < 3; ++c) p[c] = read_component(pos.data + i * pos.stride + c * csize, pos.component, pos.normalized);
      Vec3 v{static_cast<float>(world[0] * p[0] + world[4] * p[1] + world[8] * p[2] + world[12]),
             static_cast<float>(world[1] * p[0] + world[5] * p[1] + world[9] * p[2] + world[13]),
             static_cast<float>(world[2] * p[0] + world[6] * p[1] + world[10] * p[2] + world[14])};
      if (!is_finite(v))
        throw InputError(error_line(path_, wp + "vertex " + std::to_string(i) + " is NaN or Inf (after the node transform)"));
      s_.positions.push_back(v);
    }
  }

  const tinygltf::Model& m_;
  const std::string& path_;
  Scene& s_;
  size_t implicit_limit_;
};

// External buffers (and images) are read through these instead of tinygltf's defaults, which fopen
// whatever the URI names: a FIFO would block the load forever and a directory or device gives
// confusing errors. Only regular files are found; reading goes through the same checks as the scene
// file itself; nothing is ever written.
bool fs_file_exists(const std::string& abs_filename, void*) {
  std::error_code ec;
  return std::filesystem::is_regular_file(abs_filename, ec);
}
std::string fs_expand_file_path(const std::string& path, void*) { return path; }
bool fs_read_whole_file(std::vector<unsigned char>* out, std::string* err, const std::string& path, void*) {
  try {
    const std::string bytes = detail::read_file_bytes(path);
    out->assign(bytes.begin(), bytes.end());
    return true;
  } catch (const InputError& e) {
    if (err) *err += std::string(e.what()) + "\n";
    return false;
  }
}
bool fs_write_whole_file(std::string* err, const std::string& path, const std::vector<unsigned char>&, void*) {
  if (err) *err += path + ": the loader never writes files\n";
  return false;
}

// Geometry only: leave every image undecoded (see the file comment).
bool skip_image(tinygltf::Image*, const int, std::string*, std::string*, int, int, const unsigned char*, int, void*) {
  return true;
}

// A perspective camera placed by its node's world matrix becomes a view (glTF 2.0 §3.10: the
// camera looks down its local -Z with +Y up). Orthographic cameras have no pinhole equivalent in
// workloads/camera.h and are left out. Views are in traversal order, so `--view N` is the N-th
// camera met depth first.
void add_camera(const tinygltf::Model& m, int index, const Mat4& world, const std::string& path, const std::string& via,
                Scene& s) {
  if (static_cast<size_t>(index) >= m.cameras.size())
    throw InputError(error_line(path, via + "camera " + std::to_string(index) + " does not exist (" +
                                          std::to_string(m.cameras.size()) + " cameras)"));
  const tinygltf::Camera& c = m.cameras[static_cast<size_t>(index)];
  if (c.type != "perspective") return;
  const double yfov = c.perspective.yfov;
  if (!(yfov > 0 && yfov < std::numbers::pi))
    throw InputError(error_line(path, "camera " + std::to_string(index) + ": yfov " + std::to_string(yfov) +
                                          " is not in (0, pi) radians"));
  auto apply = [&](double x, double y, double z, double w) {
    return Vec3{static_cast<float>(world[0] * x + world[4] * y + world[8] * z + world[12] * w),
                static_cast<float>(world[1] * x + world[5] * y + world[9] * z + world[13] * w),
                static_cast<float>(world[2] * x + world[6] * y + world[10] * z + world[14] * w)};
  };
  CameraView v;
  v.name = c.name.empty() ? "camera " + std::to_string(index) : c.name;
  v.eye = apply(0, 0, 0, 1);
  const Vec3 fwd = apply(0, 0, -1, 0), up = apply(0, 1, 0, 0);
  if (!is_finite(v.eye) || !(length(fwd) > 0) || !(length(up) > 0) || !(length(cross(fwd, up)) > 0))
    throw InputError(error_line(path, via + "camera " + std::to_string(index) + ": its node transform is degenerate"));
  v.target = v.eye + normalize(fwd);
  v.up = normalize(up);
  v.vfov_deg = static_cast<float>(yfov * 180.0 / std::numbers::pi);
  s.views.push_back(v);
}

Scene build_scene(const tinygltf::Model& m, const std::string& path, size_t file_bytes) {
  for (const std::string& ext : m.extensionsRequired)
    if (ext == "KHR_draco_mesh_compression" || ext == "EXT_meshopt_compression" || ext == "KHR_meshopt_compression" ||
        ext == "EXT_mesh_gpu_instancing")
      throw InputError(error_line(path, "requires extension " + ext + ", which this loader does not support"));

  Scene s;
  s.name = detail::file_stem(path);
  Builder b(m, path, s, file_bytes);

  // Which nodes to draw: the default scene; without one, scene 0 (what viewers do); without any
  // scene, every node that is nobody's child.
  std::vector<int> roots;
  if (m.defaultScene >= 0) {
    if (static_cast<size_t>(m.defaultScene) >= m.scenes.size())
      throw InputError(error_line(path, "default scene " + std::to_string(m.defaultScene) + " does not exist"));
    roots = m.scenes[static_cast<size_t>(m.defaultScene)].nodes;
  } else if (!m.scenes.empty()) {
    roots = m.scenes[0].nodes;
  } else if (!m.nodes.empty()) {
    std::vector<char> is_child(m.nodes.size(), 0);
    for (const auto& n : m.nodes)
      for (int c : n.children)
        if (c >= 0 && static_cast<size_t>(c) < m.nodes.size()) is_child[static_cast<size_t>(c)] = 1;
    for (size_t i = 0; i < m.nodes.size(); ++i)
      if (!is_child[i]) roots.push_back(static_cast<int>(i));
  } else {
    // No node hierarchy at all: nothing would be displayed, but for a benchmark the meshes are the
    // content, so take each once, untransformed.
    for (size_t i = 0; i < m.meshes.size(); ++i) b.add_mesh(static_cast<int>(i), identity(), "");
    return s;
  }

  // Depth-first, pre-order, children in order. glTF node hierarchies are strict trees; a node
  // reached twice means a cycle or a shared child, either of which is malformed (and a cycle would
  // never end), so it is rejected.
  struct Item {
    int node;
    Mat4 parent;
  };
  std::vector<char> visited(m.nodes.size(), 0);
  std::vector<Item> stack;
  for (auto it = roots.rbegin(); it != roots.rend(); ++it) stack.push_back({*it, identity()});
  while (!stack.empty()) {
    Item item = stack.back();
    stack.pop_back();
    if (item.node < 0 || static_cast<size_t>(item.node) >= m.nodes.size())
      throw InputError(error_line(path, "node " + std::to_string(item.node) + " does not exist (" +
                                            std::to_string(m.nodes.size()) + " nodes)"));
    const size_t ni = static_cast<size_t>(item.node);
    if (visited[ni])
      throw InputError(error_line(path, "node " + std::to_string(ni) +
                                            " is reached twice (the node hierarchy has a cycle or a shared child)"));
    visited[ni] = 1;
    const tinygltf::Node& node = m.nodes[ni];
    const Mat4 world = mul(item.parent, local_matrix(node, path, ni));
    if (node.mesh >= 0) b.add_mesh(node.mesh, world, "node " + std::to_string(ni) + ": ");
    if (node.camera >= 0) add_camera(m, node.camera, world, path, "node " + std::to_string(ni) + ": ", s);
    for (auto it = node.children.rbegin(); it != node.children.rend(); ++it) stack.push_back({*it, world});
  }
  return s;
}

}  // namespace

Scene load_gltf(const std::string& path) {
  // Read the bytes ourselves: one place for missing/empty/directory errors, and the GLB magic decides
  // the container whatever the extension says.
  const std::string data = detail::read_file_bytes(path);
  if (data.size() > std::numeric_limits<unsigned int>::max())
    throw InputError(error_line(path, "file is larger than tinygltf's 4 GiB limit"));
  std::string base_dir = std::filesystem::path(path).parent_path().string();

  tinygltf::TinyGLTF loader;
  loader.SetImageLoader(&skip_image, nullptr);
  loader.SetFsCallbacks({&fs_file_exists, &fs_expand_file_path, &fs_read_whole_file, &fs_write_whole_file, nullptr});
  tinygltf::Model model;
  std::string err, warn;
  bool ok;
  const bool binary = data.size() >= 4 && std::memcmp(data.data(), "glTF", 4) == 0;
  try {
    if (binary)
      ok = loader.LoadBinaryFromMemory(&model, &err, &warn, reinterpret_cast<const unsigned char*>(data.data()),
                                       static_cast<unsigned int>(data.size()), base_dir);
    else
      ok = loader.LoadASCIIFromString(&model, &err, &warn, data.data(), static_cast<unsigned int>(data.size()), base_dir);
  } catch (const std::exception& e) {
    throw InputError(error_line(path, std::string("tinygltf failed: ") + e.what()));
  }
  if (!ok) {
    if (err.empty()) err = "unknown error";
    throw InputError(error_line(path, std::string(binary ? "invalid GLB file: " : "invalid glTF file: ") + err));
  }
  return build_scene(model, path, data.size());
}

}  // namespace tb
