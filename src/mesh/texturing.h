// Textures per element: an element's reflectance, emission and (alphaMode MASK) coverage are
// area averages of its material's textures over the element, read through each source
// triangle's texture coordinates (scene::Triangle::uv_base, uv_emissive). A face's elements
// split where an emissive texture or a MASK cutoff changes across them.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "mesh/mesh.h"
#include "scene/scene.h"

namespace hemirad::mesh {

// An emissive texture or MASK coverage that changes across an element splits it in four, at most
// this many times over (so a face's element becomes at most 4^kTextureLevels), and not below an
// element a texel or two across.
inline constexpr int kTextureLevels = 2;

// An element of a MASK material covering less than this share of its area is a hole: it is not
// meshed, so it neither blocks, receives nor reflects light.
inline constexpr double kMinCoverage = 0.5;

// What the textures make of one element, relative to its material's means.
struct SurfaceAverage {
    glm::dvec3 rho_scale{1.0};       // base colour texture's area average / the texture's mean, per channel
    glm::dvec3 emission_scale{1.0};  // the same for the emissive texture
    double coverage = 1.0;           // MASK: share of the area whose alpha reaches the cutoff
    double texels = 0.0;             // the finer texture's texels along the polygon's longest edge
};

// The source triangle holding p (of a and, for a quad face, b: the one where p lies deepest
// inside, so rounding on the diagonal cannot extrapolate), and p's barycentric weights in it,
// clamped to a convex combination.
struct SourcePoint {
    const scene::Triangle* triangle = nullptr;
    glm::dvec3 w{1.0 / 3.0};
};
SourcePoint source_point(const scene::Triangle& a, const scene::Triangle* b, const glm::dvec3& p);

class Texturing {
public:
    explicit Texturing(const scene::Scene& scene) : scene_(scene) {}

    // Whether a material's elements need textures sampled (a texture or MASK).
    bool samples(std::uint32_t material) const;

    // Area averages over a polygon lying in the face of source triangles a (and b).
    SurfaceAverage average(const Polygon& poly, const scene::Triangle& a, const scene::Triangle* b) const;

    // Whether an element of this material, of averages `whole`, may split in four for its
    // textures: it spans more than two texels, and a MASK cutoff crosses it or its material has
    // an emissive texture. Only then are its children's averages worth taking.
    bool may_split(std::uint32_t material, const SurfaceAverage& whole) const;
    // Whether it should: a MASK cutoff crosses it, or its children's averages (`children`, of
    // split_polygon's four) differ in emission by more than kEmissionContrast.
    bool should_split(std::uint32_t material, const SurfaceAverage& whole,
                      const std::array<SurfaceAverage, 4>& children) const;

    // An element's reflectance (vertex reflectance at its centroid x the base colour texture's
    // scale, held to [0, kMaxReflectance]) and emission (material emission x the emissive scale).
    glm::dvec3 rho(const glm::dvec3& vertex_rho, const SurfaceAverage& s) const;
    glm::dvec3 emission(std::uint32_t material, const SurfaceAverage& s) const;

    // Fills in a split element's reflectance and emission from its own polygon and sources
    // (Element::source); leaves elements of untextured materials as they are.
    void apply(Element& e) const;

private:
    // The texels along the polygon's longest edge, in each slot's level-0 texture.
    std::array<double, 2> footprint(const Polygon& poly, const scene::Triangle& a, const scene::Triangle* b) const;

    const scene::Scene& scene_;
};

// Reflectance at a point of a face of source triangles a (and b): their vertex reflectances
// interpolated (scene::Triangle::rho).
glm::dvec3 vertex_rho_at(const scene::Triangle& a, const scene::Triangle* b, const glm::dvec3& p);

}  // namespace hemirad::mesh
