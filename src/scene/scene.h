// The scene as hemirad sees it: world-space triangles with their reflectance and emission,
// the glTF mesh nodes they came from, and the cameras. Produced by scene::load (glTF 2.0).
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "scene/texture.h"

namespace hemirad::scene {

struct GltfSource;

struct Material {
    std::string name;
    glm::dvec3 base_color{1.0};   // baseColorFactor.rgb × base colour texture average (linear)
    glm::dvec3 emission{0.0};     // emissiveFactor × KHR_materials_emissive_strength × emissive texture average
    bool double_sided = false;
    // Why light passes through this surface ("alphaMode BLEND", "KHR_materials_transmission
    // 0.9"); empty for an opaque one. The see_through effect leaves such surfaces out.
    std::string see_through;
    double opacity = 1.0;  // of a see-through surface: what the render composites it with
    // Textures, sampled per element by the mesher. base_color and emission above hold the
    // textures' means; an element's own values scale them by its area average over the mean.
    TextureSlot base_texture, emissive_texture;
    bool coloured_texture = false;  // a texture's texels are not all grey
    // alphaMode MASK: the cutoff below which (baseColorFactor alpha x texture alpha) is a hole;
    // -1 for OPAQUE and BLEND.
    double alpha_cutoff = -1.0;
    double alpha_factor = 1.0;  // baseColorFactor alpha
    // Meshed as one patch and one element per face and never clustered, whatever the patch size:
    // the sky dome's faces (scene/sky.h), far larger than the scene's.
    bool coarse = false;
    bool textured() const { return base_texture || emissive_texture || alpha_cutoff >= 0.0; }
};

// One world-space triangle. Its front is the counter-clockwise side (after the node's
// transform; a negative-determinant transform has already been corrected for).
struct Triangle {
    std::array<glm::dvec3, 3> p;
    // Reflectance at each vertex: material base_color × COLOR_0 (1 where absent), clamped to
    // [0, kMaxReflectance].
    std::array<glm::dvec3, 3> rho;
    std::uint32_t material = 0;   // index into Scene::materials
    std::uint32_t node = 0;       // index into Scene::nodes
    std::uint32_t primitive = 0;  // index of the source primitive instance (mesh builder pairs
                                  // quads within one primitive only)
    // Texture coordinates of each vertex for the material's base colour (and alpha) and
    // emissive textures, KHR_texture_transform applied; zero when it has none.
    std::array<glm::vec2, 3> uv_base{}, uv_emissive{};
    std::uint8_t uv_slots = 0;  // bit 0: uv_base holds coordinates; bit 1: uv_emissive does
    // The primitive's vertex index at each corner (in p's order): baked.gltf interpolates the
    // file's attributes from them (GltfSource).
    std::array<std::uint32_t, 3> corner{};
};

// A glTF node that holds a mesh: one entry per such node, in glTF node order.
struct MeshNode {
    std::string name;  // node name, else mesh name, else "node<index>"
    int gltf_node = -1;
    glm::dmat4 world{1.0};  // the node's world transform (its triangles are in world space)
    // Added by hemirad, not the file (the sky dome): left out of baked.gltf and report.json's
    // meshes. It comes after the file's nodes.
    bool synthetic = false;
};

struct Camera {
    std::string name;
    glm::dmat4 camera_to_world{1.0};  // glTF convention: looks down local -Z, +Y up
    double yfov = 0.8;                // radians
    double aspect = 0.0;              // width / height; 0 when the file does not say
    double znear = 0.01;
};

// A KHR_lights_punctual light, placed by its node. Intensity is the light's colour times its
// intensity, in the extension's units: candela (lm/sr) for point and spot lights, lux (lm/m²)
// for directional ones. hemirad's emission is exitance in the same lumens: a light of I cd
// gives an irradiance of I cos θ / r² on a surface at distance r, in the units of emissiveFactor.
struct PunctualLight {
    enum class Type { point, spot, directional };
    Type type = Type::point;
    std::string name;
    glm::dvec3 position{0.0};             // world space
    glm::dvec3 direction{0.0, 0.0, -1.0};  // unit, world space: where a spot or directional light shines
    glm::dvec3 intensity{1.0};
    double inner_cone = 0.0, outer_cone = 0.7853981633974483;  // spot: radians from the direction
    double range = 0.0;                                          // 0: unlimited

    // The spot's falloff at angle θ from its direction (the extension's recommended smooth
    // step in cos θ, squared), 1 for a point light; times the range window where a range is set.
    double attenuation(const glm::dvec3& to_point) const;
};

// Reflectance 1 cannot conserve energy; the loader clamps to this and warns.
inline constexpr double kMaxReflectance = 0.9999;

// The largest emission (per channel, in the file's units) the loader accepts: radiosity reaches
// E / (1 - ρ), up to 10^4 E at kMaxReflectance, and baked.gltf stores it as 32-bit floats
// (at most 3.4e38). Legal glTF beyond it (emissiveStrength 1e100) is refused, not clamped.
inline constexpr double kMaxEmission = 1e30;

// A camera's aspect ratio (width / height) outside this range is clamped, with a warning: legal
// glTF, but an image 10^9 times taller than wide cannot be rendered. Neither can a field of view
// narrower than kMinYfov radians (its projection overflows), which is raised to it likewise.
inline constexpr double kMinAspect = 1.0 / 16.0, kMaxAspect = 16.0;
inline constexpr double kMinYfov = 1e-4;

struct Scene {
    std::filesystem::path path;
    std::vector<Material> materials;
    std::vector<Triangle> triangles;
    std::vector<MeshNode> nodes;
    std::vector<Camera> cameras;
    std::vector<std::shared_ptr<const Texture>> textures;  // the images materials' textures read
    std::vector<std::string> warnings;  // each already names the file
    std::size_t skipped_primitives = 0; // non-triangle modes
    std::vector<PunctualLight> lights;  // KHR_lights_punctual lights the scene's nodes place
    glm::dvec3 bbox_min{0.0}, bbox_max{0.0};
    // The file as loaded (null for scenes built in code): baked.gltf's source.
    std::shared_ptr<const GltfSource> source;

    double diagonal() const { return glm::length(bbox_max - bbox_min); }
};

// What a load may take, and a look at the files it will read before it reads them.
struct LoadOptions {
    // Memory the load may use (the scene's triangles and what the loader makes on the way,
    // scene/load_estimate.h): a file that asks for more is refused before any of it is made.
    double max_bytes = std::numeric_limits<double>::infinity();
    std::string limit_source = "the limit allows";  // for the message: "--max-memory allows"
    // Called with the scene file and every file it names (buffers, images) once its JSON is
    // read, before any of them is: the bake refuses outputs that would replace one.
    std::function<void(const std::vector<std::filesystem::path>&)> inputs;
    // A base colour or emissive texture whose image is missing or does not decode: false, the
    // material is read with its factors alone (as under a white, opaque texture) and one warning
    // per image says so; true (--strict-textures), InputError naming the image.
    bool strict_textures = false;
};

// Loads a .gltf or .glb. Throws InputError("<file>: <problem>") on bad input.
Scene load(const std::filesystem::path& file, const LoadOptions& options = {});

}  // namespace hemirad::scene
