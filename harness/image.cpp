#include "harness/image.h"

#include <png.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>

#include "harness/trace_runner.h"
#include "structures/output_file.h"
#include "traversal/registry.h"

namespace tb {

const std::vector<std::string>& image_metrics() {
  static const std::vector<std::string> m = {"nodes", "leaves", "tris", "time", "shade"};
  return m;
}

namespace {

bool counted(const std::string& metric) { return metric == "nodes" || metric == "leaves" || metric == "tris"; }

// ---- a 3x5 bitmap font (upper case, digits, a little punctuation), drawn at twice its size: the
// legend needs a few dozen characters, not a font library.
const char* glyph(char c) {
  static const std::array<std::pair<char, const char*>, 47> font = {{
      {'0', "111101101101111"}, {'1', "010110010010111"}, {'2', "111001111100111"}, {'3', "111001111001111"},
      {'4', "101101111001001"}, {'5', "111100111001111"}, {'6', "111100111101111"}, {'7', "111001001001001"},
      {'8', "111101111101111"}, {'9', "111101111001111"}, {'A', "010101111101101"}, {'B', "110101110101110"},
      {'C', "011100100100011"}, {'D', "110101101101110"}, {'E', "111100110100111"}, {'F', "111100110100100"},
      {'G', "011100101101011"}, {'H', "101101111101101"}, {'I', "111010010010111"}, {'J', "001001001101010"},
      {'K', "101101110101101"}, {'L', "100100100100111"}, {'M', "101111111101101"}, {'N', "110101101101101"},
      {'O', "010101101101010"}, {'P', "110101110100100"}, {'Q', "010101101110011"}, {'R', "110101110101101"},
      {'S', "011100010001110"}, {'T', "111010010010010"}, {'U', "101101101101111"}, {'V', "101101101101010"},
      {'W', "101101111111101"}, {'X', "101101010101101"}, {'Y', "101101010010010"}, {'Z', "111001010100111"},
      {'.', "000000000000010"}, {'-', "000000111000000"}, {'+', "000010111010000"}, {'_', "000000000000111"},
      {':', "000010000010000"}, {'/', "001001010100100"}, {'=', "000111000111000"}, {'(', "010100100100010"},
      {')', "010001001001010"}, {',', "000000000010100"}, {' ', "000000000000000"},
  }};
  const char u = char(std::toupper(static_cast<unsigned char>(c)));
  for (const auto& [k, bits] : font)
    if (k == u) return bits;
  return "111101101101111";  // anything else: a box
}

constexpr int kScale = 2, kCharW = 4 * kScale;  // 3 columns + 1 of spacing

struct Canvas {
  uint32_t w, h;
  std::vector<uint8_t> rgb;
  void put(int x, int y, const std::array<uint8_t, 3>& c) {
    if (x < 0 || y < 0 || uint32_t(x) >= w || uint32_t(y) >= h) return;
    std::copy(c.begin(), c.end(), rgb.begin() + (size_t(y) * w + size_t(x)) * 3);
  }
  void text(int x, int y, const std::string& s, const std::array<uint8_t, 3>& c) {
    for (char ch : s) {
      const char* g = glyph(ch);
      for (int r = 0; r < 5; ++r)
        for (int col = 0; col < 3; ++col)
          if (g[r * 3 + col] == '1')
            for (int dy = 0; dy < kScale; ++dy)
              for (int dx = 0; dx < kScale; ++dx) put(x + col * kScale + dx, y + r * kScale + dy, c);
      x += kCharW;
    }
  }
};

// Viridis (matplotlib's default map: perceptually uniform, readable in grey) at 9 stops.
std::array<uint8_t, 3> viridis(double v) {
  static const std::array<std::array<double, 3>, 9> stops = {{{68, 1, 84}, {71, 44, 122}, {59, 81, 139}, {44, 113, 142},
                                                               {33, 144, 141}, {39, 173, 129}, {92, 200, 99},
                                                               {170, 220, 50}, {253, 231, 37}}};
  v = std::clamp(v, 0.0, 1.0) * 8.0;
  const int i = std::min(7, int(v));
  const double f = v - i;
  std::array<uint8_t, 3> c{};
  for (int k = 0; k < 3; ++k) c[k] = uint8_t(std::lround(stops[i][k] * (1 - f) + stops[i + 1][k] * f));
  return c;
}

std::array<uint8_t, 3> colour(double v, bool grey) {
  if (!grey) return viridis(v);
  const uint8_t g = uint8_t(std::lround(std::clamp(v, 0.0, 1.0) * 255));
  return {g, g, g};
}

std::string label(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", v);
  return buf;
}

}  // namespace

void check_image_options(const ImageOptions& opt) {
  const auto& m = image_metrics();
  if (std::find(m.begin(), m.end(), opt.metric) == m.end())
    throw InputError("--metric '" + opt.metric + "': one of nodes, leaves, tris, time, shade");
  const SchemeInfo& info = find_scheme(opt.scheme);  // throws on an unknown name
  if (counted(opt.metric) && info.baseline)
    throw InputError("--metric " + opt.metric + ": " + opt.scheme +
                     " is a baseline whose traversal cannot be counted; use --metric time or shade");
  check_run_params({opt.scheme}, opt.scheme_config);
}

CostImage cost_image(Bench& bench, const ImageOptions& opt) {
  check_image_options(opt);
  WorkloadSpec spec = parse_workload(opt.workload);
  spec.width = opt.width, spec.height = opt.height, spec.view = opt.view, spec.seed = opt.seed;
  // By kind, not by the batch alone: a batch of no rays (a hard case on a scene it finds nothing
  // in, or every path gone) has as many pixels as rays. Decided before any ray is made.
  const bool camera = from_camera_pixels(spec);
  RayBatch batch = camera ? bench.rays(spec) : RayBatch{};
  if (!camera || batch.pixel.size() != batch.size())
    throw InputError("--workload " + spec.name() +
                     ": its rays do not come from camera pixels (use primary, divergence:D, bounce:k or shadow)");
  if (opt.packet > 0) batch.group_uniform(opt.packet);
  auto t = make_scheme(opt.scheme, config_for(opt.scheme, opt.scheme_config));
  t->prepare(bench.scene(), bench.cache());
  enable_ftz_daz();
  std::vector<Hit> hits(batch.size());
  std::vector<double> per_ray(batch.size(), 0.0);
  if (opt.metric == "shade") {
    trace_batch(*t, batch, hits, 1);
    for (size_t i = 0; i < batch.size(); ++i) {
      if (!hits[i].hit()) {
        per_ray[i] = std::numeric_limits<double>::quiet_NaN();
        continue;
      }
      const uint32_t p = hits[i].prim;
      const Vec3 a = bench.scene().vertex(p, 0), n = cross(bench.scene().vertex(p, 1) - a, bench.scene().vertex(p, 2) - a);
      const float len = length(n) * length(batch.rays[i].dir);
      per_ray[i] = len > 0.f ? std::fabs(dot(n, batch.rays[i].dir)) / len : 0.0;
    }
  } else {
    for (uint32_t p = 0; p < batch.num_packets(); ++p) {
      const PacketRange range{p, p + 1};
      const double n = std::max(1u, batch.packet_rays(p));
      double v = 0;
      if (opt.metric == "time") {
        // The timed path (NullProbe), best of three to drop interrupts; ns per ray of the packet.
        double best = std::numeric_limits<double>::infinity();
        for (int rep = 0; rep < 3; ++rep) {
          const auto t0 = std::chrono::steady_clock::now();
          t->trace(batch, range, hits);
          best = std::min(best, std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count());
        }
        v = best / n;
      } else {
        TraversalCounts c;
        Probe probe;
        probe.counts = &c;
        t->trace(batch, range, hits, probe);
        v = double(opt.metric == "nodes" ? c.node_ray_visits : opt.metric == "leaves" ? c.leaf_ray_visits : c.tri_tests) / n;
      }
      for (uint32_t i = batch.packet_begin[p]; i < batch.packet_begin[p + 1]; ++i) per_ray[i] = v;
    }
  }
  CostImage img;
  img.width = opt.width, img.height = opt.height;
  img.value.assign(size_t(img.width) * img.height, std::numeric_limits<double>::quiet_NaN());
  // One path per pixel: a bounce or shadow ray lands on the pixel its path started from.
  for (size_t i = 0; i < batch.size(); ++i) img.value[batch.pixel[i]] = per_ray[i];
  // Short: the legend is drawn in a 3x5 font across an image a few hundred pixels wide.
  img.unit = opt.metric == "nodes"    ? "nodes/ray"
             : opt.metric == "leaves" ? "leaves/ray"
             : opt.metric == "tris"   ? "tri tests/ray"
             : opt.metric == "time"   ? "ns/ray"
                                      : "abs(n.d)";
  return img;
}

void write_cost_png(const std::string& path, const CostImage& img, const std::string& title, bool grey) {
  constexpr uint32_t kStrip = 48;  // legend line, colour bar, its labels
  Canvas cv{img.width, img.height + kStrip, std::vector<uint8_t>(size_t(img.width) * (img.height + kStrip) * 3, 255)};
  std::vector<double> finite;
  for (double v : img.value)
    if (std::isfinite(v)) finite.push_back(v);
  std::sort(finite.begin(), finite.end());
  double top = finite.empty() ? 1.0 : grey ? 1.0 : finite.back();
  if (!grey && img.unit == "ns/ray" && !finite.empty()) top = finite[size_t(0.99 * double(finite.size() - 1))];
  if (!(top > 0)) top = 1.0;
  for (uint32_t y = 0; y < img.height; ++y)
    for (uint32_t x = 0; x < img.width; ++x) {
      const double v = img.value[size_t(y) * img.width + x];
      cv.put(int(x), int(y), std::isfinite(v) ? colour(v / top, grey) : std::array<uint8_t, 3>{255, 255, 255});
    }
  const std::array<uint8_t, 3> ink{0, 0, 0};
  const int y0 = int(img.height);
  cv.text(4, y0 + 4, title, ink);
  const int bar_x0 = 4, bar_x1 = int(img.width) - 4;
  for (int x = bar_x0; x < bar_x1; ++x)
    for (int y = y0 + 18; y < y0 + 28; ++y) cv.put(x, y, colour(double(x - bar_x0) / std::max(1, bar_x1 - bar_x0 - 1), grey));
  const std::string lo = "0", hi = label(top), mid = label(top / 2);
  cv.text(bar_x0, y0 + 32, lo, ink);
  cv.text(int(img.width) / 2 - int(mid.size()) * kCharW / 2, y0 + 32, mid, ink);
  cv.text(std::max(bar_x0 + 3 * kCharW, bar_x1 - int(hi.size()) * kCharW), y0 + 32, hi, ink);

  write_rgb_png(path, cv.w, cv.h, cv.rgb);
}

void write_rgb_png(const std::string& path, uint32_t width, uint32_t height, const std::vector<uint8_t>& rgb) {
  if (rgb.size() != size_t(width) * height * 3) throw std::logic_error("write_rgb_png: buffer size");
  png_image out{};
  out.version = PNG_IMAGE_VERSION;
  out.width = width;
  out.height = height;
  out.format = PNG_FORMAT_RGB;
  // Encoded in memory, then written as every output is (write_file_durably: temporary + rename),
  // so a failed write leaves the old image, not a cut one. The first call sizes the buffer.
  png_alloc_size_t bytes = 0;
  if (!png_image_write_to_memory(&out, nullptr, &bytes, 0, rgb.data(), 0, nullptr))
    throw InputError(path + ": cannot encode PNG (" + std::string(out.message) + ")");
  std::string png(bytes, '\0');
  if (!png_image_write_to_memory(&out, png.data(), &bytes, 0, rgb.data(), 0, nullptr))
    throw InputError(path + ": cannot encode PNG (" + std::string(out.message) + ")");
  png.resize(bytes);
  write_file_durably(path, png);
}

void run_image(Bench& bench, const ImageOptions& opt, const std::string& scene_label) {
  const CostImage img = cost_image(bench, opt);
  const std::string title = scene_label + " " + opt.workload + " " + opt.scheme + " " + img.unit;
  write_cost_png(opt.out, img, title, opt.metric == "shade");
  std::fprintf(stderr, "wrote %s (%ux%u, %s)\n", opt.out.c_str(), img.width, img.height + 48, img.unit.c_str());
}

}  // namespace tb
