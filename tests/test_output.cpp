// Output tests: per-node summaries, the baked glTF's welding, the rasterizer, image files and
// camera choice, each against values worked out by hand.
#include <OpenImageIO/imageio.h>
#include <tiny_gltf.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <glm/gtc/constants.hpp>
#include <string>
#include <vector>

#include "core/error.h"
#include "output/output.h"

namespace fs = std::filesystem;
using namespace hemirad;
using Catch::Matchers::Contains;

namespace {

// A planar element from counter-clockwise corners (seen from its front).
mesh::Element element(std::vector<glm::dvec3> corners, std::uint32_t node, bool back = false, bool has_twin = false) {
    mesh::Element e;
    e.poly.n = static_cast<int>(corners.size());
    glm::dvec3 cross_sum(0.0), sum(0.0);
    for (int i = 0; i < e.poly.n; ++i) {
        e.poly.v[i] = corners[i];
        cross_sum += glm::cross(corners[i], corners[(i + 1) % e.poly.n]);
        sum += corners[i];
    }
    e.normal = glm::normalize(cross_sum);
    e.area = 0.5 * glm::length(cross_sum);
    e.centroid = sum / double(e.poly.n);
    e.node = node;
    e.back = back;
    e.has_twin = has_twin || back;
    return e;
}

// An axis-aligned square in the plane z = `z`, facing +Z (towards a camera at the origin
// looking down −Z when z < 0), or −Z when `flipped`.
mesh::Element square_z(double x0, double y0, double x1, double y1, double z, std::uint32_t node, bool flipped = false) {
    std::vector<glm::dvec3> c = {{x0, y0, z}, {x1, y0, z}, {x1, y1, z}, {x0, y1, z}};
    if (flipped) std::swap(c[1], c[3]);
    return element(c, node);
}

scene::Scene scene_with_nodes(std::vector<std::string> names) {
    scene::Scene scene;
    scene.path = "test_scene.gltf";
    for (std::size_t i = 0; i < names.size(); ++i) scene.nodes.push_back({names[i], int(i)});
    return scene;
}

std::vector<glm::dvec3> grey(std::vector<double> values) {
    std::vector<glm::dvec3> out;
    for (double v : values) out.emplace_back(v);
    return out;
}

// A fresh directory, removed with everything in it at the end of the test.
struct TempDir {
    fs::path path;
    explicit TempDir(const std::string& name)
        : path(fs::temp_directory_path() / ("hemirad_test_output_" + name + "_" + std::to_string(getpid()))) {
        fs::remove_all(path);
        fs::create_directories(path);
    }
    ~TempDir() {
        std::error_code ignored;
        fs::remove_all(path, ignored);
    }
};

// ---- baked glTF helpers --------------------------------------------------------------------

struct LoadedGltf {
    tinygltf::Model model;
    std::string error, warning;
    bool ok = false;
};

LoadedGltf load_gltf(const fs::path& file) {
    LoadedGltf loaded;
    tinygltf::TinyGLTF loader;
    loaded.ok = loader.LoadASCIIFromFile(&loaded.model, &loaded.error, &loaded.warning, file.string());
    return loaded;
}

std::vector<glm::vec3> read_vec3(const tinygltf::Model& model, int accessor_index) {
    const tinygltf::Accessor& accessor = model.accessors.at(accessor_index);
    REQUIRE(accessor.componentType == TINYGLTF_COMPONENT_TYPE_FLOAT);
    REQUIRE(accessor.type == TINYGLTF_TYPE_VEC3);
    const tinygltf::BufferView& view = model.bufferViews.at(accessor.bufferView);
    const std::vector<unsigned char>& data = model.buffers.at(view.buffer).data;
    const std::size_t stride = std::size_t(accessor.ByteStride(view));
    std::vector<glm::vec3> out(accessor.count);
    for (std::size_t i = 0; i < accessor.count; ++i) {
        std::memcpy(&out[i], data.data() + view.byteOffset + accessor.byteOffset + i * stride, sizeof(glm::vec3));
    }
    return out;
}

std::vector<std::uint32_t> read_indices(const tinygltf::Model& model, int accessor_index) {
    const tinygltf::Accessor& accessor = model.accessors.at(accessor_index);
    REQUIRE(accessor.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT);
    const tinygltf::BufferView& view = model.bufferViews.at(accessor.bufferView);
    const std::vector<unsigned char>& data = model.buffers.at(view.buffer).data;
    std::vector<std::uint32_t> out(accessor.count);
    std::memcpy(out.data(), data.data() + view.byteOffset + accessor.byteOffset, out.size() * 4);
    return out;
}

struct Primitive {
    std::vector<glm::vec3> positions, normals, colours;
    std::vector<std::uint32_t> indices;
};

Primitive read_primitive(const tinygltf::Model& model, int mesh_index) {
    REQUIRE(model.meshes.at(mesh_index).primitives.size() == 1);
    const tinygltf::Primitive& p = model.meshes[mesh_index].primitives[0];
    return {read_vec3(model, p.attributes.at("POSITION")), read_vec3(model, p.attributes.at("NORMAL")),
            read_vec3(model, p.attributes.at("COLOR_0")), read_indices(model, p.indices)};
}

// Indices of the vertices at `position` (exactly).
std::vector<std::size_t> vertices_at(const Primitive& p, glm::vec3 position) {
    std::vector<std::size_t> found;
    for (std::size_t i = 0; i < p.positions.size(); ++i) {
        if (p.positions[i] == position) found.push_back(i);
    }
    return found;
}

// ---- render helpers ------------------------------------------------------------------------

// Camera at the origin looking down −Z, 90° vertical field of view: at distance d the image
// spans [−d, d] in x and y, so on a 64×64 image at z = −2 one unit is 16 pixels.
output::View straight_view() {
    output::View view;
    view.yfov = glm::half_pi<double>();
    view.aspect = 1.0;
    view.name = "test";
    return view;
}

glm::vec3 pixel(const output::Image& image, int x, int y) {
    const float* p = &image.rgb[(std::size_t(y) * image.width + x) * 3];
    return {p[0], p[1], p[2]};
}

}  // namespace

TEST_CASE("summarize: area-weighted means per node over front faces", "[output]") {
    const scene::Scene scene = scene_with_nodes({"floor", "light"});
    mesh::Mesh mesh;
    mesh.elements.push_back(square_z(0, 0, 1, 1, 0, 0));    // area 1
    mesh.elements.push_back(square_z(1, 0, 4, 1, 0, 0));    // area 3
    mesh::Element back = square_z(0, 0, 1, 1, 0, 0, true);  // area 1, excluded
    back.back = true;
    mesh.elements.push_back(back);
    mesh.elements.push_back(square_z(0, 0, 2, 1, 5, 1));  // area 2, node 1
    const std::vector<glm::dvec3> radiosity = {{1, 0, 2}, {3, 1, 0}, {100, 100, 100}, {0.5, 0.25, 8}};
    const std::vector<glm::dvec3> irradiance = {{2, 2, 2}, {6, 0, 4}, {100, 100, 100}, {1, 1, 1}};

    const auto summaries = output::summarize(scene, mesh, radiosity, irradiance);

    REQUIRE(summaries.size() == 2);
    CHECK(summaries[0].name == "floor");
    CHECK(summaries[0].area == Approx(4.0));
    // (1·(1,0,2) + 3·(3,1,0)) / 4 = (2.5, 0.75, 0.5); (1·(2,2,2) + 3·(6,0,4)) / 4 = (5, 0.5, 3.5)
    CHECK(summaries[0].radiosity.x == Approx(2.5));
    CHECK(summaries[0].radiosity.y == Approx(0.75));
    CHECK(summaries[0].radiosity.z == Approx(0.5));
    CHECK(summaries[0].irradiance.x == Approx(5.0));
    CHECK(summaries[0].irradiance.y == Approx(0.5));
    CHECK(summaries[0].irradiance.z == Approx(3.5));
    CHECK(summaries[1].name == "light");
    CHECK(summaries[1].area == Approx(2.0));
    CHECK(summaries[1].radiosity.z == Approx(8.0));
    CHECK(summaries[1].irradiance.x == Approx(1.0));
}

TEST_CASE("baked glTF: welded 2x2 grid with area-weighted vertex radiosity", "[output]") {
    TempDir dir("grid");
    const scene::Scene scene = scene_with_nodes({"floor"});
    mesh::Mesh mesh;
    mesh.elements = {square_z(0, 0, 1, 1, 0, 0), square_z(1, 0, 2, 1, 0, 0), square_z(0, 1, 1, 2, 0, 0),
                     square_z(1, 1, 2, 2, 0, 0)};
    const auto radiosity = grey({1, 2, 3, 4});

    // A stem that needs URI escaping exercises the buffer naming too.
    const std::string stem = GENERATE(as<std::string>{}, "baked", "my baked");
    const fs::path file = dir.path / (stem + ".gltf");
    output::write_baked_gltf(file, scene, mesh, radiosity);

    REQUIRE(fs::exists(dir.path / (stem + ".bin")));
    const LoadedGltf loaded = load_gltf(file);
    INFO(loaded.error << loaded.warning);
    REQUIRE(loaded.ok);
    CHECK(loaded.error.empty());
    CHECK(loaded.warning.empty());
    const tinygltf::Model& model = loaded.model;
    CHECK(model.asset.generator == "hemirad");
    REQUIRE(model.nodes.size() == 1);
    CHECK(model.nodes[0].name == "floor");
    REQUIRE(model.buffers.size() == 1);
    CHECK(model.buffers[0].uri == (stem == "baked" ? "baked.bin" : "my%20baked.bin"));

    const Primitive p = read_primitive(model, model.nodes[0].mesh);
    CHECK(p.positions.size() == 9);
    CHECK(p.indices.size() == 4 * 2 * 3);
    for (std::uint32_t i : p.indices) CHECK(i < 9);
    const auto centre = vertices_at(p, {1, 1, 0});
    REQUIRE(centre.size() == 1);
    CHECK(p.colours[centre[0]].x == Approx(2.5));  // (1 + 2 + 3 + 4) / 4
    const auto corner = vertices_at(p, {0, 0, 0});
    REQUIRE(corner.size() == 1);
    CHECK(p.colours[corner[0]].y == Approx(1.0));
    const auto far_corner = vertices_at(p, {2, 2, 0});
    REQUIRE(far_corner.size() == 1);
    CHECK(p.colours[far_corner[0]].z == Approx(4.0));
    const auto edge_middle = vertices_at(p, {1, 0, 0});
    REQUIRE(edge_middle.size() == 1);
    CHECK(p.colours[edge_middle[0]].x == Approx(1.5));  // (1 + 2) / 2
    CHECK(p.normals[centre[0]] == glm::vec3(0, 0, 1));

    const tinygltf::Accessor& positions = model.accessors[model.meshes[0].primitives[0].attributes.at("POSITION")];
    CHECK(positions.minValues == std::vector<double>{0, 0, 0});
    CHECK(positions.maxValues == std::vector<double>{2, 2, 0});
    REQUIRE(model.materials.size() == 1);
    CHECK(model.materials[0].extensions.count("KHR_materials_unlit") == 1);
    CHECK(model.extensionsUsed == std::vector<std::string>{"KHR_materials_unlit"});
}

TEST_CASE("baked glTF: a 90-degree crease and the two sides of a surface are not welded", "[output]") {
    TempDir dir("crease");
    const scene::Scene scene = scene_with_nodes({"corner", "sheet"});
    mesh::Mesh mesh;
    // Floor facing +Y and wall facing +X meeting along the z axis.
    mesh.elements.push_back(element({{0, 0, 0}, {0, 0, 1}, {1, 0, 1}, {1, 0, 0}}, 0));
    mesh.elements.push_back(element({{0, 0, 0}, {0, 1, 0}, {0, 1, 1}, {0, 0, 1}}, 0));
    // A doubleSided sheet: the front, and its back as a reversed polygon.
    mesh.elements.push_back(element({{0, 0, 5}, {1, 0, 5}, {1, 1, 5}, {0, 1, 5}}, 1, false, true));
    mesh.elements.push_back(element({{0, 0, 5}, {0, 1, 5}, {1, 1, 5}, {1, 0, 5}}, 1, true, true));
    const auto radiosity = grey({1, 2, 3, 4});
    const fs::path file = dir.path / "baked.gltf";
    output::write_baked_gltf(file, scene, mesh, radiosity);

    const LoadedGltf loaded = load_gltf(file);
    INFO(loaded.error << loaded.warning);
    REQUIRE(loaded.ok);
    REQUIRE(loaded.model.nodes.size() == 2);
    CHECK(loaded.model.nodes[0].name == "corner");
    CHECK(loaded.model.nodes[1].name == "sheet");

    const Primitive corner = read_primitive(loaded.model, loaded.model.nodes[0].mesh);
    CHECK(corner.positions.size() == 8);
    const auto on_edge = vertices_at(corner, {0, 0, 1});
    REQUIRE(on_edge.size() == 2);
    // Each keeps its own element's normal and value: no blur across the crease.
    for (std::size_t v : on_edge) {
        if (corner.normals[v] == glm::vec3(0, 1, 0)) {
            CHECK(corner.colours[v].x == Approx(1.0));
        } else {
            CHECK(corner.normals[v] == glm::vec3(1, 0, 0));
            CHECK(corner.colours[v].x == Approx(2.0));
        }
    }

    const Primitive sheet = read_primitive(loaded.model, loaded.model.nodes[1].mesh);
    CHECK(sheet.positions.size() == 8);
    CHECK(sheet.indices.size() == 4 * 3);
    const auto sheet_corner = vertices_at(sheet, {1, 1, 5});
    REQUIRE(sheet_corner.size() == 2);
    CHECK(sheet.colours[sheet_corner[0]].x + sheet.colours[sheet_corner[1]].x == Approx(3 + 4));
    CHECK(sheet.normals[sheet_corner[0]].z == -sheet.normals[sheet_corner[1]].z);
}

TEST_CASE("baked glTF: a shallow fold is welded and shades smoothly", "[output]") {
    TempDir dir("fold");
    const scene::Scene scene = scene_with_nodes({"fold"});
    const double c = std::cos(glm::radians(20.0)), s = std::sin(glm::radians(20.0));
    mesh::Mesh mesh;
    // Two unit squares meeting along x = 1, the second tilted up by 20° (a tessellated curve).
    mesh.elements.push_back(element({{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}}, 0));
    mesh.elements.push_back(element({{1, 0, 0}, {1 + c, 0, s}, {1 + c, 1, s}, {1, 1, 0}}, 0));
    const fs::path file = dir.path / "baked.gltf";
    output::write_baked_gltf(file, scene, mesh, grey({1, 2}));

    const LoadedGltf loaded = load_gltf(file);
    REQUIRE(loaded.ok);
    const Primitive fold = read_primitive(loaded.model, loaded.model.nodes[0].mesh);
    CHECK(fold.positions.size() == 6);
    const auto shared = vertices_at(fold, {1, 0, 0});
    REQUIRE(shared.size() == 1);
    CHECK(fold.colours[shared[0]].x == Approx(1.5));  // equal areas: (1 + 2) / 2
    // The normal halfway between the two faces': tilted 10° about the fold.
    CHECK(fold.normals[shared[0]].x == Approx(-std::sin(glm::radians(10.0))));
    CHECK(fold.normals[shared[0]].z == Approx(std::cos(glm::radians(10.0))));
}

TEST_CASE("baked glTF: an unwritable path throws InternalError", "[output]") {
    const scene::Scene scene = scene_with_nodes({"floor"});
    mesh::Mesh mesh;
    mesh.elements = {square_z(0, 0, 1, 1, 0, 0)};
    const fs::path file = fs::temp_directory_path() / "hemirad_no_such_dir" / "sub" / "baked.gltf";
    CHECK_THROWS_AS(output::write_baked_gltf(file, scene, mesh, grey({1})), InternalError);
}

TEST_CASE("render: a quad facing the camera fills exactly its pixels", "[output]") {
    const scene::Scene scene = scene_with_nodes({"quad"});
    mesh::Mesh mesh;
    mesh.elements = {square_z(-1, 0, 1, 1, -2, 0)};  // pixels x 16..47, rows 16..31 (y up)
    const output::Image image = output::render(scene, mesh, grey({0.5}), straight_view(), 64, 64);

    REQUIRE(image.width == 64);
    REQUIRE(image.height == 64);
    REQUIRE(image.rgb.size() == 64 * 64 * 3);
    int wrong = 0;
    for (int y = 0; y < 64; ++y) {
        for (int x = 0; x < 64; ++x) {
            const bool inside = x >= 16 && x < 48 && y >= 16 && y < 32;
            const glm::vec3 expected(inside ? 0.5f : 0.0f);
            if (glm::any(glm::greaterThan(glm::abs(pixel(image, x, y) - expected), glm::vec3(1e-5f)))) ++wrong;
        }
    }
    CHECK(wrong == 0);
    CHECK(pixel(image, 20, 20).x == Approx(0.5).margin(1e-5));
    CHECK(pixel(image, 20, 40).x == 0.0f);  // below the quad: background
}

TEST_CASE("render: a sample on a shared edge is drawn once, by the top-left rule", "[output]") {
    // Two quads in separate nodes (so not welded) meet on a line through a column (row) of
    // sample centres: at z = −2, pixel x = (x + 2)·16, so x = −0.71875 is pixel 20.5, the
    // middle sample column of pixel 20. The sample on the edge belongs to the right (lower)
    // quad, whose left (top) edge it is, even though the other quad is drawn first.
    const scene::Scene scene = scene_with_nodes({"first", "second"});
    mesh::Mesh mesh;
    SECTION("vertical edge") {
        mesh.elements = {square_z(-1.5, -1, -0.71875, 1, -2, 0), square_z(-0.71875, -1, 0.5, 1, -2, 1)};
        const output::Image image = output::render(scene, mesh, grey({1, 0}), straight_view(), 64, 64);
        CHECK(pixel(image, 20, 32).x == Approx(1.0 / 3.0).margin(1e-6));
    }
    SECTION("horizontal edge") {
        // y = −0.53125 is pixel row (2 − y)·16 = 40.5.
        mesh.elements = {square_z(-1, -0.53125, 1, 1, -2, 0), square_z(-1, -1.5, 1, -0.53125, -2, 1)};
        const output::Image image = output::render(scene, mesh, grey({1, 0}), straight_view(), 64, 64);
        CHECK(pixel(image, 32, 40).x == Approx(1.0 / 3.0).margin(1e-6));
    }
}

TEST_CASE("render: backs are culled as glTF viewers cull them, twinned or not", "[output]") {
    const scene::Scene scene = scene_with_nodes({"near", "wall"});
    mesh::Mesh mesh;
    mesh.elements = {square_z(-1, 0, 1, 1, -2, 0, /*flipped=*/true), square_z(-5, -5, 5, 5, -4, 1)};
    const auto radiosity = grey({0.7, 1.0});

    SECTION("one-sided: its back is culled (doubleSided false), the wall shows through") {
        const output::Image image = output::render(scene, mesh, radiosity, straight_view(), 64, 64);
        CHECK(pixel(image, 20, 20).x == Approx(1.0).margin(1e-5));
        CHECK(pixel(image, 5, 5).x == Approx(1.0).margin(1e-5));
    }
    SECTION("twinned: the back is the twin's business, the wall shows through") {
        mesh.elements[0].has_twin = true;
        const output::Image image = output::render(scene, mesh, radiosity, straight_view(), 64, 64);
        CHECK(pixel(image, 20, 20).x == Approx(1.0).margin(1e-5));
    }
}

TEST_CASE("render: the nearer surface wins whatever the drawing order", "[output]") {
    const scene::Scene scene = scene_with_nodes({"a", "b"});
    const mesh::Element near_quad = square_z(-1, 0, 1, 1, -2, 0);
    const mesh::Element far_wall = square_z(-5, -5, 5, 5, -4, 1);
    const bool near_first = GENERATE(true, false);
    mesh::Mesh mesh;
    mesh.elements =
        near_first ? std::vector<mesh::Element>{near_quad, far_wall} : std::vector<mesh::Element>{far_wall, near_quad};
    const auto radiosity = near_first ? grey({0.25, 1.0}) : grey({1.0, 0.25});
    const output::Image image = output::render(scene, mesh, radiosity, straight_view(), 64, 64);
    CHECK(pixel(image, 20, 20).x == Approx(0.25).margin(1e-5));
    CHECK(pixel(image, 5, 5).x == Approx(1.0).margin(1e-5));
}

TEST_CASE("render: a floor reaching behind the camera is clipped at the near plane", "[output]") {
    const scene::Scene scene = scene_with_nodes({"floor"});
    mesh::Mesh mesh;
    // Floor y = −1 from z = +10 (behind the camera) to z = −10, facing up.
    mesh.elements = {element({{-10, -1, 10}, {10, -1, 10}, {10, -1, -10}, {-10, -1, -10}}, 0)};
    const output::Image image = output::render(scene, mesh, grey({0.5}), straight_view(), 64, 64);
    // Horizon of the floor's far edge: y_ndc = −1/10, row 35.2. Above the eye level: nothing.
    for (int x = 0; x < 64; x += 7) {
        for (int y = 0; y < 32; ++y) CHECK(pixel(image, x, y).x == 0.0f);
        for (int y = 37; y < 64; ++y) CHECK(pixel(image, x, y).x == Approx(0.5).margin(1e-5));
    }
}

TEST_CASE("render: interpolation is perspective-correct", "[output]") {
    const scene::Scene scene = scene_with_nodes({"floor"});
    mesh::Mesh mesh;
    // Floor y = −1 in two equal strips, z ∈ [−3, −1] with B = 0 and z ∈ [−5, −3] with B = 1:
    // the welded vertex values 0, 0.5, 1 at z = −1, −3, −5 are linear in z, so the image
    // must show B(z) = (−1 − z) / 4 at the floor point each pixel sees.
    mesh.elements = {element({{-10, -1, -1}, {10, -1, -1}, {10, -1, -3}, {-10, -1, -3}}, 0),
                     element({{-10, -1, -3}, {10, -1, -3}, {10, -1, -5}, {-10, -1, -5}}, 0)};
    const output::Image image = output::render(scene, mesh, grey({0.0, 1.0}), straight_view(), 64, 64);
    for (int row = 40; row <= 60; row += 4) {
        const double y_ndc = 1.0 - 2.0 * (row + 0.5) / 64.0;
        const double z = 1.0 / y_ndc;  // the ray (x, y_ndc, −1)·t meets y = −1 at t = −1/y_ndc
        INFO("row " << row);
        CHECK(pixel(image, 32, row).x == Approx((-1.0 - z) / 4.0).margin(3e-3));
    }
}

TEST_CASE("auto_exposure: a high percentile of lit pixels maps to 0.6, 1 for black", "[output]") {
    output::Image image{20, 1, std::vector<float>(60, 0.0f)};
    CHECK(output::auto_exposure(image) == 1.0);
    // Ten lit grey pixels 1..10 among black ones: the 90th percentile of the lit is 9.
    for (int i = 0; i < 10; ++i) {
        for (int c = 0; c < 3; ++c) image.rgb[std::size_t(i * 2) * 3 + c] = float(i + 1);
    }
    CHECK(output::auto_exposure(image) == Approx(0.6 / 9.0));

    // A lone emitter pixel does not set the exposure.
    output::Image room{100, 1, std::vector<float>(300, 0.5f)};
    for (int c = 0; c < 3; ++c) room.rgb[c] = 1000.0f;
    CHECK(output::auto_exposure(room) == Approx(1.2));
}

TEST_CASE("write_exr: 32-bit float round trip, beyond half float's range", "[output]") {
    TempDir dir("exr");
    output::Image image{4, 3, std::vector<float>(36)};
    for (std::size_t i = 0; i < image.rgb.size(); ++i) image.rgb[i] = 0.25f * float(i) + 0.5f;
    image.rgb[7] = 1e30f;  // half floats end at 65504: this was written as inf
    image.rgb[8] = 0.1f;   // not representable in half
    const fs::path file = dir.path / "render.exr";
    output::write_exr(image, file);

    auto in = OIIO::ImageInput::open(file.string());
    REQUIRE(in);
    const OIIO::ImageSpec& spec = in->spec();
    CHECK(spec.width == 4);
    CHECK(spec.height == 3);
    REQUIRE(spec.nchannels == 3);
    CHECK(spec.format == OIIO::TypeDesc::FLOAT);
    std::vector<float> back(36);
    REQUIRE(in->read_image(0, 0, 0, 3, OIIO::TypeDesc::FLOAT, back.data()));
    in->close();
    CHECK(back == image.rgb);
}

TEST_CASE("write_png: exposure, shoulder and sRGB", "[output]") {
    TempDir dir("png");
    output::Image image{2, 1, {0.5f, 1.0f, 0.0f, 2.0f, 0.1f, 1000.0f}};
    const fs::path file = dir.path / "render.png";
    output::write_png(image, file, 0.5);

    auto in = OIIO::ImageInput::open(file.string());
    REQUIRE(in);
    CHECK(in->spec().width == 2);
    CHECK(in->spec().height == 1);
    REQUIRE(in->spec().nchannels == 3);
    std::vector<std::uint8_t> back(6);
    REQUIRE(in->read_image(0, 0, 0, 3, OIIO::TypeDesc::UINT8, back.data()));
    in->close();
    // Exposed: 0.25, 0.5, 0 | 1.0, 0.05, 500. Below the knee (0.8) the curve is the identity;
    // 1.0 is 0.8 + 0.2·(1/2) = 0.9; 500 is just under 1. Then sRGB: 0.25 → 0.537, 0.5 → 0.735,
    // 0.9 → 0.955, 0.05 → 0.248, ×255.
    const int expected[6] = {137, 188, 0, 243, 63, 255};
    for (int i = 0; i < 6; ++i) {
        INFO("channel " << i);
        CHECK(std::abs(int(back[i]) - expected[i]) <= 1);
    }
}

TEST_CASE("image writers throw OutputError on failure", "[output]") {
    const output::Image image{1, 1, {0.5f, 0.5f, 0.5f}};
    const fs::path bad = fs::temp_directory_path() / "hemirad_no_such_dir" / "sub" / "x";
    CHECK_THROWS_AS(output::write_exr(image, bad.string() + ".exr"), OutputError);
    CHECK_THROWS_AS(output::write_png(image, bad.string() + ".png", 1.0), OutputError);
}

TEST_CASE("choose_view: named, first, or framing camera", "[output]") {
    scene::Scene scene = scene_with_nodes({"box"});
    scene.bbox_min = {0, 0, 0};
    scene.bbox_max = {2, 4, 6};

    SECTION("no camera: framing view aimed at the bounds' centre, sphere in view") {
        const output::View view = output::choose_view(scene, "");
        CHECK(view.name == "framing");
        CHECK(view.aspect == 1.0);
        const glm::dvec3 eye(view.camera_to_world[3]);
        const glm::dvec3 forward = glm::normalize(glm::dvec3(view.camera_to_world * glm::dvec4(0, 0, -1, 0)));
        const glm::dvec3 centre(1, 2, 3);
        const glm::dvec3 to_centre = centre - eye;
        const double miss = glm::length(to_centre - glm::dot(to_centre, forward) * forward);
        CHECK(miss == Approx(0.0).margin(1e-9));
        const double radius = 0.5 * std::sqrt(4.0 + 16.0 + 36.0);
        CHECK(glm::length(to_centre) * std::sin(0.5 * view.yfov) >= radius * (1 - 1e-9));
        CHECK(glm::dot(forward, glm::dvec3(0, 0, -1)) > 0.5);  // seen from the +Z side
    }

    scene::Camera a;
    a.name = "a";
    a.camera_to_world[3] = glm::dvec4(1, 2, 3, 1);
    scene::Camera b;
    b.name = "b";
    b.aspect = 1.5;
    b.yfov = 0.5;
    scene.cameras = {a, b};

    SECTION("first camera by default, unknown aspect as 1") {
        const output::View view = output::choose_view(scene, "");
        CHECK(view.name == "a");
        CHECK(view.camera_to_world == a.camera_to_world);
        CHECK(view.aspect == 1.0);
    }
    SECTION("named camera") {
        const output::View view = output::choose_view(scene, "b");
        CHECK(view.name == "b");
        CHECK(view.aspect == 1.5);
        CHECK(view.yfov == 0.5);
    }
    SECTION("unknown name: InputError naming the file and the cameras") {
        CHECK_THROWS_AS(output::choose_view(scene, "nope"), InputError);
        CHECK_THROWS_WITH(output::choose_view(scene, "nope"),
                          Contains("test_scene.gltf") && Contains("'nope'") && Contains("a, b"));
    }
}

// ---- surroundings: see-through surfaces and the sky -----------------------------------------

namespace {

// A see-through triangle pair covering [x0, x1] × [y0, y1] at depth z (facing +Z), material m.
std::vector<scene::Triangle> pane(double x0, double y0, double x1, double y1, double z, std::uint32_t m,
                                  glm::dvec3 colour) {
    const glm::dvec3 a(x0, y0, z), b(x1, y0, z), c(x1, y1, z), d(x0, y1, z);
    scene::Triangle t1{{a, b, c}, {colour, colour, colour}, m, 0, 0};
    scene::Triangle t2{{a, c, d}, {colour, colour, colour}, m, 0, 0};
    return {t1, t2};
}

}  // namespace

TEST_CASE("render: a see-through pane blends over what lies behind it, tinted as glass or blended as a sprite",
          "[output][see_through]") {
    // A wall of radiosity 1 behind the pane (z = −4, x < 0) and one of radiosity 3 beside it
    // (x > 0), equal areas: the pane's irradiance is taken as their area mean, 2.
    scene::Scene scene = scene_with_nodes({"left", "right"});
    mesh::Mesh mesh;
    mesh.elements = {square_z(-5, -5, 0, 5, -4, 0), square_z(0, -5, 5, 5, -4, 1)};
    const auto radiosity = grey({1.0, 3.0});
    const glm::dvec3 c(0.8, 0.2, 0.1);
    scene::Material glass;
    glass.name = "glass";
    output::Surroundings around;
    around.see_through = pane(-1.5, -1, -0.5, 1, -2, 0, c);  // pixels x 8..23 at z = −2 (16 per unit)
    const double a = 0.4;
    glass.opacity = a;
    glm::dvec3 expected;
    SECTION("alphaMode BLEND: (1 − a) of the wall, untinted, and a·c·2 of its own") {
        glass.see_through = "alphaMode BLEND, mean opacity 0.40";
        expected = (1 - a) * glm::dvec3(1.0) + a * c * 2.0;
    }
    SECTION("KHR_materials_transmission: (1 − a) c of the wall, and a·c·2 of its own") {
        glass.see_through = "KHR_materials_transmission 0.6";
        expected = (1 - a) * c * 1.0 + a * c * 2.0;
    }
    scene.materials = {glass};
    const output::Image image = output::render(scene, output::weld(2, mesh, radiosity), straight_view(), 64, 64, around);
    const glm::vec3 behind = pixel(image, 16, 32);
    CHECK(behind.x == Approx(expected.x).margin(1e-4));
    CHECK(behind.y == Approx(expected.y).margin(1e-4));
    CHECK(behind.z == Approx(expected.z).margin(1e-4));
    CHECK(pixel(image, 28, 32).x == Approx(1.0).margin(1e-5));  // the wall beside the pane
    CHECK(pixel(image, 40, 32).x == Approx(3.0).margin(1e-5));
    // Without surroundings the pane is not drawn.
    CHECK(pixel(output::render(scene, output::weld(2, mesh, radiosity), straight_view(), 64, 64), 16, 32).x ==
          Approx(1.0).margin(1e-5));
}

TEST_CASE("render: a see-through pane behind an opaque surface is hidden, two panes multiply", "[output][see_through]") {
    scene::Scene scene = scene_with_nodes({"wall", "near"});
    mesh::Mesh mesh;
    mesh.elements = {square_z(-5, -5, 5, 5, -4, 0), square_z(0, -1, 1, 1, -1, 1)};
    scene::Material glass;
    glass.see_through = "alphaMode BLEND, mean opacity 0.50";
    glass.opacity = 0.5;
    scene.materials = {glass};
    output::Surroundings around;
    // Two black panes (own light 0) over the whole wall at z = −3 and −2, one behind the near quad.
    around.see_through = pane(-5, -5, 5, 5, -3, 0, glm::dvec3(0.0));
    for (const scene::Triangle& t : pane(-5, -5, 5, 5, -2, 0, glm::dvec3(0.0))) around.see_through.push_back(t);
    const output::Image image =
        output::render(scene, output::weld(2, mesh, grey({1.0, 1.0})), straight_view(), 64, 64, around);
    CHECK(pixel(image, 10, 10).x == Approx(0.25).margin(1e-5));  // the wall through both panes
    // The near quad at z = −1 stands in front of both: pixels x 32..63 at z = −1 span 32 per unit
    CHECK(pixel(image, 40, 28).x == Approx(1.0).margin(1e-5));
}

TEST_CASE("render: where a view ray escapes, the sky's exitance pi L shows and below the dome's rim and without a sky, black",
          "[output][sky]") {
    scene::Scene scene = scene_with_nodes({"quad"});
    // Bounds [−1, 1] × [−1, 1] × [−3, −1]: the dome's rim is centred at (0, −1, −2), radius 2 √12.
    scene.bbox_min = {-1, -1, -3};
    scene.bbox_max = {1, 1, -1};
    mesh::Mesh mesh;
    mesh.elements = {square_z(-1, 0, 1, 1, -2, 0)};  // pixels x 16..47, rows 16..31
    const auto weld = output::weld(1, mesh, grey({0.5}));
    output::Surroundings around;
    around.sky = scene::Sky{2.0, 2.0};
    const output::Image image = output::render(scene, weld, straight_view(), 64, 64, around);
    CHECK(pixel(image, 20, 20).x == Approx(0.5).margin(1e-5));     // the quad
    CHECK(pixel(image, 32, 33).x == Approx(2.0 * M_PI).epsilon(1e-6));  // ahead, just below the quad: sky
    CHECK(pixel(image, 4, 4).y == Approx(2.0 * M_PI).epsilon(1e-6));
    // Rows further down look down steeply enough that the ray leaves the dome's sphere below its
    // rim (row 40: 1 − 0.257 t with t ≈ 9.1).
    CHECK(pixel(image, 32, 40).x == 0.0f);
    CHECK(pixel(image, 32, 63).x == 0.0f);
    CHECK(pixel(output::render(scene, weld, straight_view(), 64, 64), 32, 33).x == 0.0f);

    SECTION("a graded sky: the radiance at the elevation where the ray meets the dome") {
        around.sky = scene::Sky{1.0, 3.0};
        const output::Image graded = output::render(scene, weld, straight_view(), 64, 64, around);
        // The ray through pixel (4, 20)'s centre, from the eye 1 above the rim's centre and 2 behind it.
        const double y_ndc = 1.0 - 2.0 * (20 + 0.5) / 64.0, x_ndc = 2.0 * (4 + 0.5) / 64.0 - 1.0;
        const glm::dvec3 d = glm::normalize(glm::dvec3(x_ndc, y_ndc, -1.0)), o(0.0, 1.0, 2.0);
        const double R = 2.0 * std::sqrt(12.0), b = glm::dot(o, d);
        const double t = -b + std::sqrt(b * b - (glm::dot(o, o) - R * R));
        const double sin_elevation = (o.y + t * d.y) / R;
        CHECK(sin_elevation > 0.0);
        // (The pixel is the mean of 3 × 3 samples about this ray: equal to a few parts in 10^5.)
        CHECK(pixel(graded, 4, 20).x == Approx(M_PI * (1.0 + 2.0 * sin_elevation)).epsilon(1e-4));
    }
}

TEST_CASE("choose_view: a closed room without a camera is framed from inside, an object from outside", "[output][view]") {
    // A 6 × 3 × 4 box of 12 triangles, its faces turned inwards (a room) or outwards (an object),
    // in metres or in millimetres (a SketchUp export).
    const bool inwards = GENERATE(true, false);
    const double scale = GENERATE(1.0, 1000.0);
    scene::Scene scene = scene_with_nodes({"box"});
    scene.materials.push_back(scene::Material{});
    const glm::dvec3 lo = scale * glm::dvec3(-3, 0, -2), hi = scale * glm::dvec3(3, 3, 2);
    scene.bbox_min = lo;
    scene.bbox_max = hi;
    const auto corner = [&](int i) { return glm::dvec3(i & 1 ? hi.x : lo.x, i & 2 ? hi.y : lo.y, i & 4 ? hi.z : lo.z); };
    // Each face's corners counter-clockwise seen from outside.
    const int faces[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
    for (const auto& f : faces) {
        std::array<glm::dvec3, 4> q = {corner(f[0]), corner(f[1]), corner(f[2]), corner(f[3])};
        if (inwards) std::swap(q[1], q[3]);
        scene.triangles.push_back({{q[0], q[1], q[2]}, {}, 0, 0, 0});
        scene.triangles.push_back({{q[0], q[2], q[3]}, {}, 0, 0, 0});
    }
    const output::View view = output::choose_view(scene, "");
    const glm::dvec3 eye(view.camera_to_world[3]);
    if (inwards) {
        CHECK(view.name == "framing (inside)");
        CHECK(glm::all(glm::greaterThan(eye, lo)));
        CHECK(glm::all(glm::lessThan(eye, hi)));
        CHECK(eye.y == Approx(1.5 * scale));  // half the room's height: below 1.6 m, or not in metres
        const glm::dvec3 forward(view.camera_to_world * glm::dvec4(0, 0, -1, 0));
        CHECK(forward.x == Approx(-1.0));  // along the longer side
    } else {
        CHECK(view.name == "framing");
        CHECK(eye.z > hi.z);
    }
}
