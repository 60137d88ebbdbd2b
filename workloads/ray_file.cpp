#include "workloads/ray_file.h"

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "structures/output_file.h"
#include "structures/scene.h"

namespace tb {
namespace {

constexpr char kRayMagic[8] = {'T', 'B', 'R', 'A', 'Y', 'S', '1', '\0'};
constexpr char kHitMagic[8] = {'T', 'B', 'H', 'I', 'T', 'S', '1', '\0'};

// A file's bytes, built in memory and written by write_file_durably (temporary + rename): a failed
// or interrupted write never leaves a cut ray or hit file where an older one was.
struct Bytes {
  std::string data;
  void put(const void* p, size_t n) { data.append(static_cast<const char*>(p), n); }
};

// Opens and sizes a file for reading; rejects directories and unreadable paths.
std::ifstream open_in(const std::string& path, uint64_t& size) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) throw InputError(path + ": is a directory, not a file");
  // Before opening: opening a FIFO blocks until a writer appears, and a device has no size.
  if (std::filesystem::exists(path, ec) && !std::filesystem::is_regular_file(path, ec))
    throw InputError(path + ": is not a regular file");
  std::ifstream f(path, std::ios::binary);
  if (!f) throw InputError(path + ": cannot open for reading");
  size = std::filesystem::file_size(path, ec);
  if (ec) throw InputError(path + ": cannot read its size");
  return f;
}

template <class T>
void read_exact(std::ifstream& f, T* data, size_t n, const std::string& path, const char* what) {
  f.read(reinterpret_cast<char*>(data), std::streamsize(n * sizeof(T)));
  if (!f) throw InputError(path + ": truncated while reading " + what);
}

}  // namespace

void write_rays(const std::string& path, const RayBatch& b) {
  Bytes f;
  const uint64_t count = b.rays.size();
  // Uniform = exactly what group_uniform(packet_size) rebuilds on reading, empty packets included
  // (a table like {0, 0} must not come back as {0}).
  bool uniform = b.packet_size > 0 && b.num_packets() == (count + b.packet_size - 1) / b.packet_size;
  for (uint32_t p = 0; uniform && p < b.num_packets(); ++p)
    uniform &= b.packet_begin[p] == uint64_t(p) * b.packet_size;
  const uint32_t packet_count = uniform ? 0 : b.num_packets();
  f.data.reserve(24 + count * 32 + (packet_count ? (size_t(packet_count) + 1) * 4 : 0));
  f.put(kRayMagic, 8);
  f.put(&count, 8);
  f.put(&b.packet_size, 4);
  f.put(&packet_count, 4);
  for (const Ray& r : b.rays) {
    const float v[8] = {r.org.x, r.org.y, r.org.z, r.dir.x, r.dir.y, r.dir.z, r.tmin, r.tmax};
    f.put(v, sizeof v);
  }
  if (packet_count) f.put(b.packet_begin.data(), (size_t(packet_count) + 1) * 4);
  write_file_durably(path, f.data);
}

RayBatch read_rays(const std::string& path) {
  uint64_t size = 0;
  auto f = open_in(path, size);
  char magic[8];
  uint64_t count = 0;
  uint32_t packet_size = 0, packet_count = 0;
  if (size < 24) throw InputError(path + ": too short for a ray file header (" + std::to_string(size) + " bytes)");
  read_exact(f, magic, 8, path, "the magic");
  if (std::memcmp(magic, kRayMagic, 8) != 0) throw InputError(path + ": not a travbench ray file (bad magic)");
  read_exact(f, &count, 1, path, "the count");
  read_exact(f, &packet_size, 1, path, "the packet size");
  read_exact(f, &packet_count, 1, path, "the packet count");
  // The size the header implies, in long double: 32 bytes a ray of a count near 2^64 would wrap.
  const long double expect = 24.0L + 32.0L * (long double)count + (packet_count ? 4.0L * ((long double)packet_count + 1) : 0.0L);
  if (count > (size - 24) / 32 || expect != (long double)size) {
    char need[32];
    std::snprintf(need, sizeof need, "%.0Lf", expect);
    throw InputError(path + ": header says " + std::to_string(count) + " rays and " + std::to_string(packet_count) +
                     " packets, which needs " + need + " bytes, but the file has " + std::to_string(size));
  }
  if (packet_size == 0) throw InputError(path + ": packet size is 0");
  RayBatch b;
  b.rays.resize(count);
  for (uint64_t i = 0; i < count; ++i) {
    float v[8];
    read_exact(f, v, 8, path, "rays");
    b.rays[i] = {{v[0], v[1], v[2]}, v[6], {v[3], v[4], v[5]}, v[7]};
  }
  if (packet_count) {
    b.packet_begin.resize(packet_count + 1);
    read_exact(f, b.packet_begin.data(), packet_count + 1, path, "the packet table");
    b.packet_size = packet_size;
  } else {
    b.group_uniform(packet_size);
  }
  b.common_origin = !b.rays.empty();
  for (const Ray& r : b.rays) b.common_origin &= r.org == b.rays[0].org;
  try {
    b.validate();
  } catch (const InputError& e) {
    throw InputError(path + ": " + e.what());
  }
  return b;
}

void write_hits(const std::string& path, const std::vector<Hit>& hits) {
  Bytes f;
  const uint64_t count = hits.size();
  f.data.reserve(16 + count * sizeof(Hit));
  f.put(kHitMagic, 8);
  f.put(&count, 8);
  f.put(hits.data(), count * sizeof(Hit));
  write_file_durably(path, f.data);
}

std::vector<Hit> read_hits(const std::string& path) {
  uint64_t size = 0;
  auto f = open_in(path, size);
  if (size < 16) throw InputError(path + ": too short for a hit file header");
  char magic[8];
  uint64_t count = 0;
  read_exact(f, magic, 8, path, "the magic");
  if (std::memcmp(magic, kHitMagic, 8) != 0) throw InputError(path + ": not a travbench hit file (bad magic)");
  read_exact(f, &count, 1, path, "the count");
  if (count > (size - 16) / 16 || 16 + count * 16 != size)
    throw InputError(path + ": header says " + std::to_string(count) + " hits but the file has " +
                     std::to_string(size) + " bytes");
  std::vector<Hit> hits(count);
  read_exact(f, hits.data(), count, path, "hits");
  return hits;
}

}  // namespace tb
