// Machine-limit calibration (src/bench/calibrate.cpp): the peak rate of a tight vectorized z-buffer
// loop and the streaming copy bandwidth of one device, the yardsticks the benchmark divides the
// form-factor engines' throughput by.
//
// zbuffer_fill: every triangle's three edge functions and depth plane have integer coefficients
// small enough (below 2^24 at every pixel) that each product and sum is exact in float, so any
// evaluation order, FMA or not, gives the host model's bits; no FP_CONTRACT pragma is needed and
// the compiler may fuse as the hardware likes.

// Tuning knobs; the host passes its per-device values as -D options.
#ifndef HEMIRAD_CALIB_WIDTH
#define HEMIRAD_CALIB_WIDTH 16  // pixels per strip row, the vector width: 4, 8 or 16
#endif
#ifndef HEMIRAD_CALIB_ROWS
#define HEMIRAD_CALIB_ROWS 4  // rows of a work-item's strip, held in registers: 1, 2, 4, 8 or 16
#endif
#ifndef HEMIRAD_CALIB_COPY_RUNS
#define HEMIRAD_CALIB_COPY_RUNS 0  // 1: bandwidth_copy gives each work-item a contiguous run (CPUs)
#endif
#ifndef HEMIRAD_CALIB_FAR
#define HEMIRAD_CALIB_FAR 16777216.0f  // the cleared depth, 2^24: beyond every synthetic depth
#endif

#define CALIB_CAT_(a, b) a##b
#define CALIB_CAT(a, b) CALIB_CAT_(a, b)
#define floatW CALIB_CAT(float, HEMIRAD_CALIB_WIDTH)
#define intW CALIB_CAT(int, HEMIRAD_CALIB_WIDTH)
#define vstoreW CALIB_CAT(vstore, HEMIRAD_CALIB_WIDTH)

#if HEMIRAD_CALIB_WIDTH == 4
#define CALIB_LANES ((float4)(0, 1, 2, 3))
#elif HEMIRAD_CALIB_WIDTH == 8
#define CALIB_LANES ((float8)(0, 1, 2, 3, 4, 5, 6, 7))
#elif HEMIRAD_CALIB_WIDTH == 16
#define CALIB_LANES ((float16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15))
#else
#error "HEMIRAD_CALIB_WIDTH must be 4, 8 or 16"
#endif

// One work-item per strip of HEMIRAD_CALIB_WIDTH x HEMIRAD_CALIB_ROWS pixels of a width x height
// tile (both multiples of the strip), dimension 1 the tile: every tile sees the same triangles, so
// the host can run as many tiles as the device needs work-groups without changing the answer. Triangle t is
// triangles[4t .. 4t+3]: three edges and the depth plane, each (a, b, c, unused) for a*x + b*y + c
// at pixel (x, y); a pixel is inside where all three edges are >= 0. The nearest inside triangle
// wins, the earlier one on a depth tie. z and id are row-major per tile, tile after tile.
__kernel void zbuffer_fill(__global const float4* restrict triangles, int count, int width, int height,
                           __global float* restrict z_out, __global int* restrict id_out) {
    const int strips_x = width / HEMIRAD_CALIB_WIDTH;
    const int strip = (int)get_global_id(0);
    const int x0 = (strip % strips_x) * HEMIRAD_CALIB_WIDTH;
    const int y0 = (strip / strips_x) * HEMIRAD_CALIB_ROWS;
    const floatW x = (floatW)((float)x0) + CALIB_LANES;

    floatW z[HEMIRAD_CALIB_ROWS];
    intW id[HEMIRAD_CALIB_ROWS];
#pragma unroll
    for (int r = 0; r < HEMIRAD_CALIB_ROWS; ++r) {
        z[r] = (floatW)(HEMIRAD_CALIB_FAR);
        id[r] = (intW)(-1);
    }

    for (int t = 0; t < count; ++t) {
        const float4 e0 = triangles[4 * t], e1 = triangles[4 * t + 1], e2 = triangles[4 * t + 2];
        const float4 d = triangles[4 * t + 3];
        // The strip's first row in full, then each next row one addition per plane away, as a
        // rasterizer steps its edge functions.
        const float y = (float)y0;
        floatW w0 = e0.x * x + (e0.y * y + e0.z);
        floatW w1 = e1.x * x + (e1.y * y + e1.z);
        floatW w2 = e2.x * x + (e2.y * y + e2.z);
        floatW depth = d.x * x + (d.y * y + d.z);
#pragma unroll
        for (int r = 0; r < HEMIRAD_CALIB_ROWS; ++r) {
            const intW hit = (w0 >= 0.0f) & (w1 >= 0.0f) & (w2 >= 0.0f) & (depth < z[r]);
            z[r] = select(z[r], depth, hit);
            id[r] = select(id[r], (intW)(t), hit);
            w0 += e0.y;
            w1 += e1.y;
            w2 += e2.y;
            depth += d.y;
        }
    }

    const size_t tile_base = get_global_id(1) * (size_t)width * (size_t)height;
#pragma unroll
    for (int r = 0; r < HEMIRAD_CALIB_ROWS; ++r) {
        const size_t row = tile_base + (size_t)(y0 + r) * (size_t)width + (size_t)x0;
        vstoreW(z[r], 0, z_out + row);
        vstoreW(id[r], 0, id_out + row);
    }
}

// Streams src to dst, per_item uint4s per work-item. With HEMIRAD_CALIB_COPY_RUNS (CPUs) each
// work-item copies its own contiguous run, which a core walks front to back; without (GPUs) a
// work-group copies one run, its items interleaved so that neighbours touch neighbouring addresses.
__kernel void bandwidth_copy(__global const uint4* restrict src, __global uint4* restrict dst, uint per_item) {
#if HEMIRAD_CALIB_COPY_RUNS
    const size_t step = 1;
    const size_t base = get_global_id(0) * (size_t)per_item;
#else
    const size_t step = get_local_size(0);
    const size_t base = get_group_id(0) * (size_t)per_item * step + get_local_id(0);
#endif
    for (uint k = 0; k < per_item; ++k) dst[base + k * step] = src[base + k * step];
}
