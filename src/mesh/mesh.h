// Patches (shooters) and elements (receivers, children of patches) built from the scene's
// triangles. Coplanar triangle pairs that form a convex quad are meshed as one grid.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <vector>

#include <glm/glm.hpp>

#include "scene/scene.h"

namespace hemirad::mesh {

// A planar convex triangle or quad, counter-clockwise seen from its front.
struct Polygon {
    std::array<glm::dvec3, 4> v{};
    int n = 3;  // 3 or 4
};

struct Element {
    Polygon poly;
    glm::dvec3 normal{0.0};    // unit, front side
    glm::dvec3 centroid{0.0};  // area centroid
    double area = 0.0;
    glm::dvec3 rho{0.0};       // reflectance (COLOR_0 interpolated at the centroid)
    glm::dvec3 emission{0.0};
    std::uint32_t patch = 0;   // parent patch
    std::uint32_t node = 0;    // scene mesh node
    std::uint32_t material = 0;
    // True when the same surface also exists facing the other way (a doubleSided material):
    // then this element's back is the twin's front, so the back need not be drawn as a blocker.
    bool has_twin = false;
    // True for the reversed copy of a doubleSided triangle (its glTF back face). Per-node
    // averages in the report use front faces only.
    bool back = false;
    // Of a coarse material (the sky dome): refinement never splits it.
    bool coarse = false;
    // The scene triangles whose face holds this element (scene::Scene::triangles; the second
    // only for a quad of two, else kNoSource): textures are read through them.
    std::array<std::uint32_t, 2> source{0xffffffffu, 0xffffffffu};
};

inline constexpr std::uint32_t kNoPatch = 0xffffffffu;
inline constexpr std::uint32_t kNoSource = 0xffffffffu;

// A shooter: one cell of a face's grid, or two of a triangle's side by side (a planar polygon), or
// a cluster of small faces (adjacent, of one material and node, their normals within kClusterCos
// of each other's), whose shape is only the union of its elements and which shoots along its mean
// normal from its area centroid, raised where needed to be in front of all of its elements'
// planes. Where that point lies across another face, a flat cluster shoots from its face nearest
// the point instead (a wall clustered across a cornice), a curved one is halved until its halves'
// points are clear (a ball's bottom cap on a floor). A cluster may also hold clusters apart from
// it, next to it (Settings::cluster_apart: a crown's leaves), and then shoots from the mean of its
// parts' points (`apart`).
struct Patch {
    Polygon poly;              // the cell; n = 0 for a cluster of faces (see elements)
    glm::dvec3 normal{0.0};    // unit: the cell's normal, or a cluster's area-weighted mean
    glm::dvec3 centroid{0.0};  // where the patch shoots from: a cell's area centroid (a cluster: see above)
    double area = 0.0;
    glm::dvec3 emission{0.0};  // area-weighted over its elements
    std::uint32_t first_element = 0;
    std::uint32_t element_count = 0;
    std::uint32_t node = 0;
    // The same surface facing the other way (doubleSided), or kNoPatch. A cell's shot skips its
    // twin's elements as its own (all in its base plane); a cluster's skips neither.
    std::uint32_t twin = kNoPatch;
    // A cluster that took in clusters apart from it (Settings::cluster_apart): it shoots from the
    // mean of its parts' points, and its own elements get their siblings' light, not the point's
    // (formfactor::NearFieldEngine).
    bool apart = false;
    bool cluster() const { return poly.n == 0; }
};

// One hemicube of a punctual light: from `position`, the half-space along unit `axis`. A point
// light is two, back to back; a spot light one, along its direction (its cone is at most a
// half-space wide).
struct LightShooter {
    glm::dvec3 position{0.0};
    glm::dvec3 axis{0.0, 1.0, 0.0};
    std::uint32_t light = 0;  // index of the light in scene::Scene::lights
};

// A directional light that shines (a sun: KHR_lights_punctual "directional", or --sun, of
// intensity > 0): a parallel shot along unit `direction`, the way its light travels
// (formfactor::Shooter::Kind::directional).
struct DirectionalShooter {
    glm::dvec3 direction{0.0, -1.0, 0.0};
    std::uint32_t light = 0;  // index of the light in scene::Scene::lights
};

// A point a final gather shoots from (formfactor::Shooter::Kind::point): an output vertex, just
// inside its surface, looking along the surface's normal there.
struct GatherPoint {
    glm::dvec3 position{0.0};
    glm::dvec3 normal{0.0, 1.0, 0.0};  // unit
};

struct Settings {
    double patch_size = 0.0;    // maximum patch edge length, scene units (> 0)
    double element_size = 0.0;  // maximum element edge length, scene units (> 0, <= patch_size)
    // Faces that fit in one patch join adjacent ones into clusters of up to about a patch's size,
    // so that the shooter count follows the scene's area, not its triangle count. Off: a patch
    // per small face (what meshes were before clusters).
    bool cluster = true;
    // Clusters also take whole clusters nearby that share no edge with them (the same material
    // and node, normals within kClusterCos, within half a patch diagonal) where every part still
    // sees the joined cluster's shooting point: a tree's leaves, a grille, a string of lights
    // shoot as one patch, not one each. A bake turns it on (`--no-cluster-apart` leaves it off);
    // off here, for the benchmark's meshes and the tests that build meshes themselves: connected
    // faces only.
    bool cluster_apart = false;
};

// Faces of a cluster have normals within this cosine (25°) of its first face's normal: close
// enough that one hemicube, from the area centroid along the mean normal, stands for all of them.
inline constexpr double kClusterCos = 0.9063077870366499;

struct Mesh {
    std::vector<Patch> patches;
    std::vector<LightShooter> lights;  // the scene's punctual lights' hemicubes
    std::vector<DirectionalShooter> directions;  // the scene's shining directional lights, in light order
    std::vector<GatherPoint> gather_points;  // the final gather's points (solve/final_gather.h); set by it
    // A gather's drawing (solve::gather_mesh): element c stands for the solved mesh's elements
    // [drawn_from[c], drawn_from[c + 1]); one entry more than the elements. Empty otherwise.
    std::vector<std::uint32_t> drawn_from;
    std::vector<Element> elements;  // elements of patch p are [first_element, first_element + element_count)
    std::size_t dropped_triangles = 0;  // zero or near-zero area
    std::size_t quads = 0;              // triangle pairs meshed as quads
    std::size_t clusters = 0;           // patches that are clusters of several faces (per side)
    std::size_t split_clusters = 0;     // halvings of curved clusters (per side): see Patch
    std::size_t moved_clusters = 0;     // flat clusters that shoot from a face's centroid: see Patch
    std::size_t joined_clusters = 0;    // clusters that took in clusters apart from them (per side): Settings::cluster_apart
    std::size_t texture_splits = 0;     // elements split where an emissive texture or MASK coverage changes (once for both sides)
    std::size_t holes = 0;              // elements left out as MASK holes (once for both sides)
    // Patches whose elements' emission differs (an emissive texture's edge crosses them), each
    // split into one patch per element so that light leaves from where it is emitted (per side);
    // and those left whole, shooting from their centroid, once kMaxEmissionShooters was reached.
    std::size_t emission_splits = 0;
    std::size_t emission_unsplit = 0;
};

// Patches that splitting emitters (Mesh::emission_splits) may add, at most: this many plus a
// sixteenth of the patches the scene would have without them, so that a large emissive atlas
// adds a bounded share of shooters (and of a matrix solve's rows).
inline constexpr double kMaxEmissionShooters = 1024.0;

// What a mesh will hold, counted before any of it is built (doubles: any size can be counted).
struct Counts {
    double patches = 0.0;
    double elements = 0.0;
};

// Meshes the scene. `before` (if set) is told the counts once the faces are known and before
// any patch is built, and may throw to stop: a bake checks there that the mesh and the rest of
// the bake fit in memory.
Mesh build(const scene::Scene& scene, const Settings& settings,
           const std::function<void(const Counts&)>& before = {});

// The hemicubes of a scene's point and spot lights, for Mesh::lights (directional lights have
// none): two back to back for a point light, one along a spot light's direction.
std::vector<LightShooter> light_shooters(const std::vector<scene::PunctualLight>& lights);

// The parallel shots of a scene's directional lights of intensity > 0, for Mesh::directions, in
// light order.
std::vector<DirectionalShooter> directional_shooters(const std::vector<scene::PunctualLight>& lights);

// Normal (unit, front side), area centroid and area of a planar convex polygon.
struct Shape {
    glm::dvec3 normal{0.0};
    glm::dvec3 centroid{0.0};
    double area = 0.0;
};
Shape shape_of(const Polygon& poly);

// The longest edge of a polygon.
double longest_edge(const Polygon& poly);

// Surfaces whose normals differ by less than this are one smoothly shaded surface: the welder
// shares their vertices (output/welded_mesh.cpp), and where they touch it is no contact line
// (contact.h). Tessellated curved surfaces (a 16-segment cylinder turns 22.5° per facet) then
// shade smoothly while 45° chamfers and 90° corners stay crisp.
inline constexpr double kCreaseAngle = 40.0 * 3.14159265358979323846 / 180.0;  // radians

}  // namespace hemirad::mesh
