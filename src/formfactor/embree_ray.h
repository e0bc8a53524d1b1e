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

// The height above the shooter's plane below which a ray's hits are the plane itself: what the
// reference's base-plane clip is (1e-9 of the scene's extent, base_plane_epsilon), raised to what
// floats resolve. The origin and the triangles' corners are floats, each rounded by up to 2^-24 of
// the extent (6e-8), so a hit on the shooter's own plane is computed up to a few of those above
// it: 1e-6 of the extent is 16 of them. Geometry nearer the shooter's plane than that is not seen
// (the reference sees it from 1e-9 on); an object lying 1e-5 of the scene above a floor is.
inline float ray_clearance(const mesh::Mesh& mesh) {
    return static_cast<float>(1e3 * base_plane_epsilon(mesh));
}

// Lane r of a packet: from the frame's origin along the local direction (x, y, z), z > 0 the
// part along the shooter's normal, hits counted from `clearance` above the shooter's plane on
// (at t = clearance / z: a plane, as the reference clips, not a sphere around the origin, which
// let the rays of a shooter lying just above a surface it faces pass through it).
inline void set_packet_ray(RTCRayHit16& rh, int r, const FloatFrame& f, float x, float y, float z, float clearance) {
    rh.ray.org_x[r] = f.org[0];
    rh.ray.org_y[r] = f.org[1];
    rh.ray.org_z[r] = f.org[2];
    rh.ray.dir_x[r] = x * f.u[0] + y * f.v[0] + z * f.w[0];
    rh.ray.dir_y[r] = x * f.u[1] + y * f.v[1] + z * f.w[1];
    rh.ray.dir_z[r] = x * f.u[2] + y * f.v[2] + z * f.w[2];
    rh.ray.tnear[r] = clearance / z;
    rh.ray.tfar[r] = std::numeric_limits<float>::infinity();
    rh.ray.time[r] = 0.0f;
    rh.ray.mask[r] = ~0u;
    rh.ray.id[r] = static_cast<unsigned>(r);
    rh.ray.flags[r] = 0;
    rh.hit.geomID[r] = RTC_INVALID_GEOMETRY_ID;
}

}  // namespace hemirad::formfactor
