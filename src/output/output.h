// Everything a bake writes besides report.json: per-node summaries, the baked glTF, images.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "mesh/mesh.h"
#include "output/welded_mesh.h"
#include "scene/scene.h"
#include "scene/sky.h"

namespace hemirad::output {


// Area-weighted averages over one scene mesh node's front-face elements (report.json "meshes").
struct NodeSummary {
    std::string name;
    double area = 0.0;
    glm::dvec3 radiosity{0.0};
    glm::dvec3 irradiance{0.0};
};
std::vector<NodeSummary> summarize(const scene::Scene& scene, const mesh::Mesh& mesh,
                                   const std::vector<glm::dvec3>& radiosity,
                                   const std::vector<glm::dvec3>& irradiance);

// Per-vertex radiosity: vertices shared between elements of one node and side are welded and
// get the area-weighted average of the elements around them (no cracks, no seams).
// Writes `file` (.gltf) and its buffer beside it (same stem, .bin). One glTF node per scene
// mesh node, named as in the scene; COLOR_0 holds linear radiosity; materials are unlit
// (KHR_materials_unlit) so any viewer shows the baked light.
// With `gathered`, its radiosity at the vertices instead of the elements' averages.
void write_baked_gltf(const std::filesystem::path& file, const scene::Scene& scene,
                      const mesh::Mesh& mesh, const std::vector<glm::dvec3>& radiosity,
                      const VertexLight* gathered = nullptr);
// … from a weld already made (its values the light written).
void write_baked_gltf(const std::filesystem::path& file, const scene::Scene& scene, const WeldedMesh& welded);

// The user's scene back (--output-mode scene): the file the scene was loaded from
// (scene.source), its nodes, names, transforms, materials, textures, samplers, cameras, lights,
// skins, animations and extras kept, each baked mesh node given a mesh of its own whose
// primitives hold the refined element mesh (welded as above, in the node's local space) with
// the file's vertex attributes interpolated at its vertices, and the baked light:
// - `_RADIOSITY`: linear radiosity B; `_IRRADIANCE`: linear irradiance H (incident light);
// - `COLOR_0`: what a viewer multiplies with the material, in display range: tone(exposure × H)
//   × the file's own COLOR_0 under an unlit copy of the material (KHR_materials_unlit: base
//   colour texture kept at full resolution, so the viewer shows ρ × H = B); for an emitting
//   material tone(exposure × B) under an unlit white one.
// doubleSided surfaces get a primitive side for each face (each side its own light), under
// materials that are not doubleSided. Primitives with nothing baked (see-through, other modes)
// and meshes of nodes not baked are copied as they were. Images the file names by uri are
// referred to where they are (a path relative to `final_dir`, where baked.gltf will lie); embedded
// ones are copied into the buffer. Writes `file` and its buffer (same stem, .bin). Returns
// warnings (each a line) for what could not be carried over. With `gathered`, its light at the
// vertices instead of the elements' averages.
std::vector<std::string> write_scene_gltf(const std::filesystem::path& file, const std::filesystem::path& final_dir,
                                          const scene::Scene& scene,
                                          const mesh::Mesh& mesh, const std::vector<glm::dvec3>& radiosity,
                                          const std::vector<glm::dvec3>& irradiance, double exposure,
                                          const VertexLight* gathered = nullptr);
// … from a weld of `mesh` already made (`light`: its values the radiosity written) and the
// irradiance at its vertices.
std::vector<std::string> write_scene_gltf(const std::filesystem::path& file, const std::filesystem::path& final_dir,
                                          const scene::Scene& scene, const mesh::Mesh& mesh, const WeldedMesh& light,
                                          const VertexValues& incident, double exposure);

// A linear RGB image, row 0 at the top.
struct Image {
    int width = 0, height = 0;
    std::vector<float> rgb;  // width × height × 3
};

struct View {
    glm::dmat4 camera_to_world{1.0};  // looks down local −Z, +Y up (glTF)
    double yfov = 0.8;                // radians
    double aspect = 1.0;              // width / height
    std::string name;                 // camera name, or "framing" / "framing (inside)" for the generated ones
};

// The named camera, else the scene's first camera, else, for a closed room (rays from its
// centre meet the faces that show, almost all around), one inside it looking across from near
// one end at eye height ("framing (inside)"), else one framing the scene's bounds from outside.
// Throws InputError naming the scene file when `camera_name` is given but not found.
View choose_view(const scene::Scene& scene, const std::string& camera_name);

// A view from `from` looking at `at` (+Y up; +Z up when looking straight up or down), with a
// vertical field of view of yfov radians and a 4:3 image. Throws InputError when the two points
// are the same.
View look_view(const glm::dvec3& from, const glm::dvec3& at, double yfov);

// Rasterizes the element mesh (welded, smooth per-vertex radiosity as in the baked glTF) from
// `view`: z-buffered, perspective-correct, supersampled. Back faces of one-sided surfaces are
// black; nothing hit is black. With `gathered`, its radiosity at the vertices.
Image render(const scene::Scene& scene, const mesh::Mesh& mesh,
             const std::vector<glm::dvec3>& radiosity, const View& view, int width, int height,
             const VertexLight* gathered = nullptr);
// … of a weld already made (its values the radiosity drawn).
Image render(const scene::Scene& scene, const WeldedMesh& welded, const View& view, int width, int height);

// What a render shows besides the baked mesh, so that it looks like the scene.
struct Surroundings {
    // The see-through triangles the bake left out (scene::apply_see_through), in the scene's
    // materials: composited over what lies behind them, both faces, farthest first. A surface
    // of opacity a and colour c (its reflectance) passes (1 − a) of the light behind it (times c
    // for KHR_materials_transmission, whose glass is tinted; as is for alphaMode BLEND, as
    // viewers blend) and shows a·c·H of its own, H its irradiance, taken as the area mean of the
    // drawn radiosity (in a closed room the area means of irradiance and radiosity are equal).
    std::vector<scene::Triangle> see_through;
    // The --sky seen where a view ray escapes: the dome's exitance π·L at the elevation (from the
    // dome's centre) where the ray meets it, in radiosity's units; black below the dome's rim.
    std::optional<scene::Sky> sky;
};
Image render(const scene::Scene& scene, const WeldedMesh& welded, const View& view, int width, int height,
             const Surroundings& around);

// The see-through triangles of `scene` (Material::see_through), before the effect removes them.
std::vector<scene::Triangle> see_through_triangles(const scene::Scene& scene);

// Exposure that puts the 90th percentile of lit pixels (emitters are too few to matter) at
// 0.6 linear, about 0.8 on the display.
double auto_exposure(const Image& image);

// render.png's tone curve, on linear values: identity up to a knee (0.8), then a shoulder that
// approaches 1 smoothly.
double tone(double x);

// Linear 32-bit float EXR, and a tone-mapped (exposure, then filmic-free Reinhard-style
// shoulder, then sRGB) 8-bit PNG. Both through the image back-end (src/image); a failed write
// throws OutputError.
void write_exr(const Image& image, const std::filesystem::path& file);
void write_png(const Image& image, const std::filesystem::path& file, double exposure);

}  // namespace hemirad::output
