// Ray and hit files (docs/FILE_FORMATS.md): so any scheme, or an outside renderer, can replay
// exactly the same rays. Little-endian.
//   rays: "TBRAYS1\0", uint64 count, uint32 packet_size, uint32 packet_count (0 = uniform packets
//         of packet_size), count x 8 floats (org.xyz dir.xyz tmin tmax), then, when
//         packet_count > 0, packet_count + 1 uint32 packet start offsets.
//   hits: "TBHITS1\0", uint64 count, count x (float t, uint32 prim, float u, float v).
#pragma once
#include <string>
#include <vector>

#include "workloads/ray_batch.h"

namespace tb {

void write_rays(const std::string& path, const RayBatch& batch);
RayBatch read_rays(const std::string& path);  // validates; throws InputError
void write_hits(const std::string& path, const std::vector<Hit>& hits);
std::vector<Hit> read_hits(const std::string& path);

}  // namespace tb
