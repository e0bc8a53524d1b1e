// Hemicube form factors on an OpenCL device, cell for cell the scalar reference's result
// (src/formfactor/reference.cpp): the same double-precision operations in the same order, no
// contraction into FMAs, up to the projected vertices, which are snapped to fixed point; from
// there the inside test is exact integer arithmetic, evaluated in any order. For a batch of
// shots (dimension 1 of every NDRange), per shot: setup (cull, clip and project each element on
// each face into packed records with their cell boxes, then count them per tile) -> scan
// (per-tile list offsets) -> scatter (record indices into per-tile lists) -> raster, on GPUs one
// work-group per tile and one work-item per cell, on CPUs (raster_records) one work-item per
// tile walking its records: inside and depth tests, the cell's id, the winner's delta form
// factor added in 64-bit fixed point.
//
// This file holds the pragmas, the shared types, the tuning knobs and the `layout` check; the
// stages are in files of their own, included here in order (cmake/EmbedKernels.cmake inlines
// them, with #line directives, so a build log names the real file and line). The host builds
// this one program.
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL EXTENSION cl_khr_int64_base_atomics : enable
#pragma OPENCL FP_CONTRACT OFF

#include "hemicube_types.h"

// Tuning knobs; the host passes its per-device values as -D options.
#ifndef HEMIRAD_TILE
#define HEMIRAD_TILE 16  // raster tile edge in cells: a raster work-group is TILE*TILE items
#endif
#ifndef HEMIRAD_WG
#define HEMIRAD_WG 64  // work-group size of the per-patch and per-record kernels
#endif
#ifndef HEMIRAD_RASTER_WG
#define HEMIRAD_RASTER_WG 4  // work-group size of raster_records (one work-item per tile)
#endif
#ifndef HEMIRAD_COUNT_COPIES
#define HEMIRAD_COUNT_COPIES 1  // copies of the per-tile counters, one per work-group mod this: less contention
#endif
#ifndef HEMIRAD_LANES
#define HEMIRAD_LANES 4  // cells per row step of raster_records: 4 or 8 (double8 on AVX-512)
#endif
#ifndef HEMIRAD_SETUP_LANES
#define HEMIRAD_SETUP_LANES 0  // 1: setup takes HR_SETUP_LANES elements per work-item in double8 (CPUs)
#endif
#ifndef HEMIRAD_CULL
#define HEMIRAD_CULL 1  // 0: no bounding-sphere test per lane group (the host sets it with its cluster culling)
#endif
#ifndef HEMIRAD_SCAN_WG
#define HEMIRAD_SCAN_WG 256  // the single work-group of the tile-offset scan, a power of two
#endif

#include "hemicube_common.cl"          // shared helpers: frame, clipping, fixed point, strides
#include "hemicube_setup.cl"           // setup; it includes setup_lanes.cl and cull.cl
#include "hemicube_scan.cl"            // scan and scatter: the per-tile record lists
#include "hemicube_raster.cl"          // raster shared parts and `raster` (GPUs)
#include "hemicube_raster_records.cl"  // raster_records (CPUs)

// The sizes of the shared structs as this compiler lays them out; the host compares them with
// its own before the first shot.
__kernel void layout(__global int* sizes) {
    sizes[0] = (int)sizeof(HrElement);
    sizes[1] = (int)sizeof(HrPatch);
    sizes[2] = (int)sizeof(HrShot);
    sizes[3] = (int)sizeof(HrRecord);
}
