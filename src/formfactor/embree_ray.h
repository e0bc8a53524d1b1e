// The rays of the Embree peer (embree_engine.cpp) and of its plain-loop bound
// (bench/embree_plain.cpp), set by one function, so that the bound casts exactly the peer's rays.
#pragma once

#include <embree3/rtcore.h>

#include <array>
#include <limits>

#include "formfactor/hemicube.h"

namespace hemirad::formfactor {

// A shot's frame in floats: its origin, and the world directions of the hemicube's u, v, w.
struct FloatFrame {
    std::array<float, 3> org{}, u{}, v{}, w{};
};

inline FloatFrame float_frame(const Frame& frame) {
    FloatFrame f;
    for (int a = 0; a < 3; ++a) {
        f.org[a] = static_cast<float>(frame.origin[a]);
        f.u[a] = static_cast<float>(frame.u[a]);
        f.v[a] = static_cast<float>(frame.v[a]);
        f.w[a] = static_cast<float>(frame.w[a]);
    }
    return f;
}

// Lane r of a packet: from the frame's origin along the local direction (x, y, z), from tnear on.
inline void set_packet_ray(RTCRayHit16& rh, int r, const FloatFrame& f, float x, float y, float z, float tnear) {
    rh.ray.org_x[r] = f.org[0];
    rh.ray.org_y[r] = f.org[1];
    rh.ray.org_z[r] = f.org[2];
    rh.ray.dir_x[r] = x * f.u[0] + y * f.v[0] + z * f.w[0];
    rh.ray.dir_y[r] = x * f.u[1] + y * f.v[1] + z * f.w[1];
    rh.ray.dir_z[r] = x * f.u[2] + y * f.v[2] + z * f.w[2];
    rh.ray.tnear[r] = tnear;
    rh.ray.tfar[r] = std::numeric_limits<float>::infinity();
    rh.ray.time[r] = 0.0f;
    rh.ray.mask[r] = ~0u;
    rh.ray.id[r] = static_cast<unsigned>(r);
    rh.ray.flags[r] = 0;
    rh.hit.geomID[r] = RTC_INVALID_GEOMETRY_ID;
}

}  // namespace hemirad::formfactor
