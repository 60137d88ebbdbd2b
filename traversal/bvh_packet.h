// What the three BVH packet schemes share (thesis §2.2.2, §3.3; Overbeck et al. 2008 naming:
// bvh_masked, bvh_ranged, bvh_partition): the packet's rays as SoA groups of 8 (AVX2), the 8-wide
// ray/box and ray/triangle tests, and the packet bounds used for early misses — a frustum of
// four planes for packets with a common origin, interval arithmetic (IA) over origins and
// reciprocal directions for all packets.
//
// Robustness contract (the same as the single-ray schemes): the box test is the conservative,
// NaN-aware slab test of kernels.h evaluated lane-wise; the IA bounds are built from exactly the
// quantities the per-ray slab test computes, so by monotonic rounding they never cull a node any
// ray of the packet would enter; frustum planes are fitted to the rays, proven to hold every ray
// by a float check whose margin exceeds its rounding error, and are evaluated against boxes and
// triangles with such a margin too. The box and triangle tests are the kernel library's
// (traversal/kernels.h: slab<8>, watertight_inside<8>, moller<8>, plane<8>), so every lane
// computes the very same values as the one-ray tests; the rare lanes whose ray is parallel to a
// triangle's plane go to the scalar kernel.
//
// The concepts live in focused headers, all included here:
//   packet.h          the packet (SoA groups), loading rays, storing hits, sub-packets
//   packet_bounds.h   interval-arithmetic and frustum bounds, their box/triangle culling tests
//   packet_frustum.h  fitting the frustum and the split planes to a packet
//   packet_box.h      packet vs box (slab<8>)
//   packet_tri.h      packet vs triangle (the kernel library's 8-wide tests)
#pragma once
#include "traversal/packet.h"
#include "traversal/packet_box.h"
#include "traversal/packet_bounds.h"
#include "traversal/packet_frustum.h"
#include "traversal/packet_tri.h"
