// scene::load on small glTF files written here, checked against hand-computed positions,
// materials and names, and against malformed files that must be rejected with one line.
#include <OpenImageIO/imageio.h>
#include <sys/stat.h>
#include <tiny_gltf.h>

#include <algorithm>
#include <array>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <glm/glm.hpp>
#include <iterator>
#include <limits>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <vector>

#include "core/error.h"
#include "scene/scene.h"
#include "test_scenes.h"

namespace {

namespace fs = std::filesystem;
using glm::dvec3;
using hemirad::scene::kMaxReflectance;
using hemirad::scene::Scene;

// A fresh directory per test case, removed afterwards.
class TempDir {
public:
    TempDir() {
        std::random_device rd;
        path_ = fs::temp_directory_path() / ("hemirad_scene_test_" + std::to_string(rd()) + std::to_string(rd()));
        fs::create_directories(path_);
    }
    ~TempDir() {
        std::error_code ec;
        fs::remove_all(path_, ec);
    }
    TempDir(const TempDir&) = delete;
    TempDir& operator=(const TempDir&) = delete;
    fs::path operator/(const std::string& name) const { return path_ / name; }

private:
    fs::path path_;
};

// Builds a small glTF model in memory: one buffer that every accessor points into.
struct ModelBuilder {
    tinygltf::Model model;

    ModelBuilder() {
        model.asset.version = "2.0";
        model.buffers.resize(1);
    }

    int view(const void* bytes, std::size_t n, std::size_t stride = 0) {
        std::vector<unsigned char>& data = model.buffers[0].data;
        while (data.size() % 4 != 0) data.push_back(0);  // glTF wants aligned accessors
        tinygltf::BufferView bv;
        bv.buffer = 0;
        bv.byteOffset = data.size();
        bv.byteLength = n;
        bv.byteStride = stride;
        const auto* p = static_cast<const unsigned char*>(bytes);
        data.insert(data.end(), p, p + n);
        model.bufferViews.push_back(bv);
        return int(model.bufferViews.size()) - 1;
    }

    int accessor(int view, int component_type, int type, std::size_t count, bool normalized = false) {
        tinygltf::Accessor a;
        a.bufferView = view;
        a.componentType = component_type;
        a.type = type;
        a.count = count;
        a.normalized = normalized;
        model.accessors.push_back(a);
        return int(model.accessors.size()) - 1;
    }

    int positions(const std::vector<glm::vec3>& p) {
        const int v = view(p.data(), p.size() * sizeof(glm::vec3));
        return accessor(v, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, p.size());
    }
    template <typename Index>
    int indices(const std::vector<Index>& i) {
        const int type = sizeof(Index) == 1   ? TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE
                         : sizeof(Index) == 2 ? TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT
                                              : TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
        const int v = view(i.data(), i.size() * sizeof(Index));
        return accessor(v, type, TINYGLTF_TYPE_SCALAR, i.size());
    }
    int colors_u8(const std::vector<std::array<std::uint8_t, 4>>& c) {
        const int v = view(c.data(), c.size() * 4);
        return accessor(v, TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE, TINYGLTF_TYPE_VEC4, c.size(), true);
    }

    static tinygltf::Primitive primitive(int position, int indices = -1, int material = -1,
                                         int mode = TINYGLTF_MODE_TRIANGLES) {
        tinygltf::Primitive p;
        p.attributes["POSITION"] = position;
        p.indices = indices;
        p.material = material;
        p.mode = mode;
        return p;
    }

    int mesh(const std::string& name, std::vector<tinygltf::Primitive> primitives) {
        tinygltf::Mesh m;
        m.name = name;
        m.primitives = std::move(primitives);
        model.meshes.push_back(m);
        return int(model.meshes.size()) - 1;
    }

    int node(const std::string& name, int mesh) {
        tinygltf::Node n;
        n.name = name;
        n.mesh = mesh;
        model.nodes.push_back(n);
        return int(model.nodes.size()) - 1;
    }
    tinygltf::Node& at(int node) { return model.nodes[std::size_t(node)]; }

    int material(const std::string& name, std::vector<double> base_color) {
        tinygltf::Material m;
        m.name = name;
        m.pbrMetallicRoughness.baseColorFactor = std::move(base_color);
        m.emissiveFactor = {0.0, 0.0, 0.0};  // tinygltf writes an empty array otherwise
        model.materials.push_back(m);
        return int(model.materials.size()) - 1;
    }

    void scene(std::vector<int> roots) {
        tinygltf::Scene s;
        s.nodes = std::move(roots);
        model.scenes = {s};
        model.defaultScene = 0;
    }

    // The triangle (0,0,0) (1,0,0) (0,1,0): front facing +z.
    int unit_triangle_mesh(const std::string& name = "tri", int material = -1) {
        const int pos = positions({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
        return mesh(name, {primitive(pos, -1, material)});
    }
};

fs::path write(const tinygltf::Model& model, const fs::path& file) {
    tinygltf::TinyGLTF gltf;
    const bool binary = file.extension() == ".glb";
    REQUIRE(gltf.WriteGltfSceneToFile(&model, file.string(), true, true, true, binary));
    return file;
}

bool near(const dvec3& a, const dvec3& b, double eps = 1e-9) {
    return glm::length(a - b) <= eps;
}

// Asserts every vertex of t, in order, equals the hand-computed position.
void check_triangle(const hemirad::scene::Triangle& t, const std::array<dvec3, 3>& expected) {
    for (int k = 0; k < 3; ++k) {
        INFO("vertex " << k << ": got (" << t.p[k].x << ", " << t.p[k].y << ", " << t.p[k].z << "), want ("
                       << expected[k].x << ", " << expected[k].y << ", " << expected[k].z << ")");
        CHECK(near(t.p[k], expected[k]));
    }
}

using hemirad::test::load_error;

void check_rejected(const fs::path& file, const std::string& problem) {
    const std::string message = load_error(file);
    INFO(message);
    CHECK(message.rfind(file.string() + ": ", 0) == 0);  // starts with the file
    CHECK(message.find(problem) != std::string::npos);
    CHECK(message.find('\n') == std::string::npos);
}

int count_warnings(const Scene& scene, const std::string& needle) {
    return int(std::count_if(scene.warnings.begin(), scene.warnings.end(),
                             [&](const std::string& w) { return w.find(needle) != std::string::npos; }));
}

constexpr double kHalfSqrt2 = 0.70710678118654752440;

}  // namespace

TEST_CASE("TRS node transform places vertices where hand-computed", "[scene]") {
    TempDir dir;
    ModelBuilder b;
    const int n = b.node("n", b.unit_triangle_mesh());
    b.at(n).translation = {10, 0, 0};
    b.at(n).rotation = {0, 0, kHalfSqrt2, kHalfSqrt2};  // 90° about +z: (x, y) -> (-y, x)
    b.at(n).scale = {2, 3, 4};
    b.scene({n});

    // p' = T + R(S p): (1,0,0) -> (2,0,0) -> (0,2,0) -> (10,2,0); (0,1,0) -> (0,3,0) -> (-3,0,0) -> (7,0,0)
    const std::array<dvec3, 3> want{dvec3(10, 0, 0), dvec3(10, 2, 0), dvec3(7, 0, 0)};
    for (const char* name : {"trs.gltf", "trs.glb"}) {
        SECTION(name) {
            const Scene s = hemirad::scene::load(write(b.model, dir / name));
            REQUIRE(s.triangles.size() == 1);
            check_triangle(s.triangles[0], want);
            CHECK(near(s.bbox_min, dvec3(7, 0, 0)));
            CHECK(near(s.bbox_max, dvec3(10, 2, 0)));
            CHECK(s.path == dir / name);
        }
    }
}

TEST_CASE("upper-case .GLB loads the same triangles as .gltf", "[scene]") {
    TempDir dir;
    ModelBuilder b;
    const int n = b.node("n", b.unit_triangle_mesh());
    b.at(n).translation = {0, 0, -2};
    b.scene({n});
    // Written as glb, then renamed: the extension test must ignore case.
    write(b.model, dir / "a.glb");
    fs::rename(dir / "a.glb", dir / "a.GLB");
    const Scene binary = hemirad::scene::load(dir / "a.GLB");
    const Scene ascii = hemirad::scene::load(write(b.model, dir / "a.gltf"));
    const std::array<dvec3, 3> want{dvec3(0, 0, -2), dvec3(1, 0, -2), dvec3(0, 1, -2)};
    REQUIRE(binary.triangles.size() == 1);
    REQUIRE(ascii.triangles.size() == 1);
    check_triangle(binary.triangles[0], want);
    check_triangle(ascii.triangles[0], want);
}

TEST_CASE("node matrix is read column-major", "[scene]") {
    TempDir dir;
    ModelBuilder b;
    const int n = b.node("n", b.unit_triangle_mesh());
    // Columns: x -> (0,0,-2), y -> (0,1,0), z -> (1,0,0), translation (5,6,7).
    b.at(n).matrix = {0, 0, -2, 0, 0, 1, 0, 0, 1, 0, 0, 0, 5, 6, 7, 1};
    b.scene({n});
    const Scene s = hemirad::scene::load(write(b.model, dir / "m.gltf"));
    REQUIRE(s.triangles.size() == 1);
    // det = 0*(1*0-0*0) - 0*... : columns (0,0,-2),(0,1,0),(1,0,0) -> det = +2, no flip.
    check_triangle(s.triangles[0], {dvec3(5, 6, 7), dvec3(5, 6, 5), dvec3(5, 7, 7)});
}

TEST_CASE("two-level hierarchy composes parent * child", "[scene]") {
    TempDir dir;
    ModelBuilder b;
    const int child = b.node("child", b.unit_triangle_mesh());
    b.at(child).translation = {1, 0, 0};
    const int parent = b.node("parent", -1);
    b.at(parent).translation = {0, 0, 5};
    b.at(parent).scale = {2, 2, 2};
    b.at(parent).children = {child};
    b.scene({parent});

    const Scene s = hemirad::scene::load(write(b.model, dir / "h.gltf"));
    REQUIRE(s.triangles.size() == 1);
    // p' = (0,0,5) + 2 * (p + (1,0,0))
    check_triangle(s.triangles[0], {dvec3(2, 0, 5), dvec3(4, 0, 5), dvec3(2, 2, 5)});
    REQUIRE(s.nodes.size() == 1);  // the parent holds no mesh
    CHECK(s.nodes[0].name == "child");
    CHECK(s.nodes[0].gltf_node == child);
}

TEST_CASE("negative scale keeps the file's front face", "[scene]") {
    TempDir dir;
    ModelBuilder b;
    const int n = b.node("mirror", b.unit_triangle_mesh());
    b.at(n).scale = {-1, 1, 1};
    b.scene({n});

    const Scene s = hemirad::scene::load(write(b.model, dir / "neg.gltf"));
    REQUIRE(s.triangles.size() == 1);
    const auto& t = s.triangles[0];
    // The file's front is +z. Mirroring x maps the half-space z > 0 onto itself (normals go
    // by the inverse transpose: (0,0,1) -> (0,0,1)), so the front must still face +z. The
    // mirrored vertices (0,0,0) (-1,0,0) (0,1,0) in file order would wind towards -z.
    const dvec3 normal = glm::normalize(glm::cross(t.p[1] - t.p[0], t.p[2] - t.p[0]));
    CHECK(near(normal, dvec3(0, 0, 1)));
    std::vector<dvec3> got(t.p.begin(), t.p.end());
    for (const dvec3& want : {dvec3(0, 0, 0), dvec3(-1, 0, 0), dvec3(0, 1, 0)}) {
        CHECK(std::any_of(got.begin(), got.end(), [&](const dvec3& p) { return near(p, want); }));
    }
}

TEST_CASE("KHR_materials_emissive_strength multiplies emissiveFactor", "[scene]") {
    TempDir dir;
    ModelBuilder b;
    const int m = b.material("lamp", {1, 1, 1, 1});
    b.model.materials[m].emissiveFactor = {1.0, 0.5, 0.25};
    tinygltf::Value::Object ext;
    ext["emissiveStrength"] = tinygltf::Value(8.0);
    b.model.materials[m].extensions["KHR_materials_emissive_strength"] = tinygltf::Value(ext);
    b.model.extensionsUsed = {"KHR_materials_emissive_strength"};
    b.scene({b.node("n", b.unit_triangle_mesh("tri", m))});

    const Scene s = hemirad::scene::load(write(b.model, dir / "e.gltf"));
    REQUIRE(s.triangles.size() == 1);
    const auto& mat = s.materials.at(s.triangles[0].material);
    CHECK(mat.name == "lamp");
    CHECK(near(mat.emission, dvec3(8, 4, 2)));
}

TEST_CASE("doubleSided, COLOR_0 times baseColorFactor, reflectance 1 clamped once", "[scene]") {
    TempDir dir;
    ModelBuilder b;
    const int m = b.material("paint", {0.5, 1.0, 0.25, 1.0});
    b.model.materials[m].doubleSided = true;
    const int plain = b.material("plain", {0.5, 0.5, 0.5, 1.0});
    const int pos = b.positions({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
    const int col = b.colors_u8({{255, 255, 255, 0}, {51, 102, 204, 255}, {0, 255, 0, 255}});
    tinygltf::Primitive coloured = ModelBuilder::primitive(pos, -1, m);
    coloured.attributes["COLOR_0"] = col;
    // The coloured primitive twice: the clamp warning still comes once per material.
    b.scene({b.node("a", b.mesh("a", {coloured, coloured})),
             b.node("b", b.mesh("b", {ModelBuilder::primitive(pos, -1, plain)}))});

    const Scene s = hemirad::scene::load(write(b.model, dir / "c.gltf"));
    REQUIRE(s.triangles.size() == 3);
    const auto& t = s.triangles[0];
    CHECK(s.materials.at(t.material).double_sided);
    CHECK_FALSE(s.materials.at(s.triangles[2].material).double_sided);
    // (0.5, 1, 0.25) × colour; the alpha 0 of vertex 0 must not matter; 1 -> kMaxReflectance.
    CHECK(near(t.rho[0], dvec3(0.5, kMaxReflectance, 0.25)));
    CHECK(near(t.rho[1], dvec3(0.5 * 0.2, 1.0 * 0.4, 0.25 * 0.8)));
    CHECK(near(t.rho[2], dvec3(0.0, kMaxReflectance, 0.0)));
    for (const dvec3& rho : s.triangles[2].rho) CHECK(near(rho, dvec3(0.5)));
    CHECK(count_warnings(s, "clamped to 0.9999") == 1);
    CHECK(count_warnings(s, "'paint'") == 1);
}

TEST_CASE("base colour texture is averaged in linear space", "[scene]") {
    TempDir dir;
    ModelBuilder b;
    const int m = b.material("textured", {0.5, 1.0, 1.0, 1.0});
    tinygltf::Image img;
    img.width = 2;
    img.height = 1;
    img.component = 4;
    img.bits = 8;
    img.pixel_type = TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE;
    img.mimeType = "image/png";
    img.image = {255, 128, 0, 255, 255, 0, 0, 255};
    b.model.images.push_back(img);
    tinygltf::Texture tex;
    tex.source = 0;
    b.model.textures.push_back(tex);
    b.model.materials[m].pbrMetallicRoughness.baseColorTexture.index = 0;
    b.scene({b.node("n", b.unit_triangle_mesh("tri", m))});

    const Scene s = hemirad::scene::load(write(b.model, dir / "t.gltf"));
    REQUIRE(s.triangles.size() == 1);
    // sRGB 128 is linear ((128/255 + 0.055) / 1.055)^2.4 = 0.2158605; averaged with 0 -> 0.1079302.
    // Averaging the encoded values first would give 64 -> 0.0512695 instead.
    const dvec3 want(0.5 * 1.0, 0.2158605 / 2, 0.0);
    CHECK(near(s.materials.at(0).base_color, want, 1e-6));
    CHECK(near(s.triangles[0].rho[0], want, 1e-6));
}

TEST_CASE("non-indexed and 8/16/32-bit indexed primitives load, LINES is skipped", "[scene]") {
    TempDir dir;
    ModelBuilder b;
    const int quad = b.positions({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}});
    const int soup = b.positions({{0, 0, 1}, {1, 0, 1}, {0, 1, 1}, {0, 0, 2}, {1, 0, 2}, {0, 1, 2}});
    const int i16 = b.indices(std::vector<std::uint16_t>{0, 1, 2, 2, 1, 3});
    const int i32 = b.indices(std::vector<std::uint32_t>{3, 2, 1});
    const int i8 = b.indices(std::vector<std::uint8_t>{1, 3, 2});
    const int lines = b.indices(std::vector<std::uint16_t>{0, 1, 1, 3});
    b.scene({b.node("n", b.mesh("mixed", {
                                             ModelBuilder::primitive(soup),
                                             ModelBuilder::primitive(quad, i16),
                                             ModelBuilder::primitive(quad, i32),
                                             ModelBuilder::primitive(quad, i8),
                                             ModelBuilder::primitive(quad, lines, -1, TINYGLTF_MODE_LINE),
                                         }))});

    const Scene s = hemirad::scene::load(write(b.model, dir / "p.gltf"));
    REQUIRE(s.triangles.size() == 6);
    check_triangle(s.triangles[0], {dvec3(0, 0, 1), dvec3(1, 0, 1), dvec3(0, 1, 1)});
    check_triangle(s.triangles[1], {dvec3(0, 0, 2), dvec3(1, 0, 2), dvec3(0, 1, 2)});
    check_triangle(s.triangles[2], {dvec3(0, 0, 0), dvec3(1, 0, 0), dvec3(0, 1, 0)});
    check_triangle(s.triangles[3], {dvec3(0, 1, 0), dvec3(1, 0, 0), dvec3(1, 1, 0)});
    check_triangle(s.triangles[4], {dvec3(1, 1, 0), dvec3(0, 1, 0), dvec3(1, 0, 0)});
    check_triangle(s.triangles[5], {dvec3(1, 0, 0), dvec3(1, 1, 0), dvec3(0, 1, 0)});
    const std::array<std::uint32_t, 6> primitive{0, 0, 1, 1, 2, 3};
    for (std::size_t i = 0; i < 6; ++i) CHECK(s.triangles[i].primitive == primitive[i]);
    CHECK(s.skipped_primitives == 1);
    CHECK(count_warnings(s, "mode LINES is not triangles; skipped") == 1);
    CHECK(count_warnings(s, "mesh 'mixed' primitive 4") == 1);
    // No material: the documented default grey.
    CHECK(near(s.triangles[0].rho[0], dvec3(0.8)));
}

TEST_CASE("bufferView byteStride is respected", "[scene]") {
    TempDir dir;
    ModelBuilder b;
    // xyz then one float of padding the loader must step over.
    const std::vector<float> interleaved{0, 0, 0, 99, 4, 0, 0, 99, 0, 5, 0, 99};
    const int v = b.view(interleaved.data(), interleaved.size() * sizeof(float), 16);
    const int pos = b.accessor(v, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, 3);
    b.scene({b.node("n", b.mesh("m", {ModelBuilder::primitive(pos)}))});
    const Scene s = hemirad::scene::load(write(b.model, dir / "stride.gltf"));
    REQUIRE(s.triangles.size() == 1);
    check_triangle(s.triangles[0], {dvec3(0, 0, 0), dvec3(4, 0, 0), dvec3(0, 5, 0)});
}

TEST_CASE("mesh node names: node name, else mesh name, else node<index>", "[scene]") {
    TempDir dir;
    ModelBuilder b;
    const int tri = b.positions({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
    const int n0 = b.node("floor", b.mesh("floor_mesh", {ModelBuilder::primitive(tri)}));
    const int n1 = b.node("", b.mesh("lamp", {ModelBuilder::primitive(tri)}));
    const int n2 = b.node("", b.mesh("", {ModelBuilder::primitive(tri)}));
    b.scene({n2, n0, n1});  // scene order differs from node order on purpose

    const Scene s = hemirad::scene::load(write(b.model, dir / "names.gltf"));
    REQUIRE(s.nodes.size() == 3);
    CHECK(s.nodes[0].name == "floor");
    CHECK(s.nodes[1].name == "lamp");
    CHECK(s.nodes[2].name == "node2");
    for (int i = 0; i < 3; ++i) CHECK(s.nodes[std::size_t(i)].gltf_node == i);
    REQUIRE(s.triangles.size() == 3);
    for (std::uint32_t i = 0; i < 3; ++i) CHECK(s.triangles[i].node == i);
}

TEST_CASE("perspective camera: yfov, aspect, znear and a scale-free world transform", "[scene]") {
    TempDir dir;
    ModelBuilder b;
    tinygltf::Camera cam;
    cam.type = "perspective";
    cam.name = "view";
    cam.perspective.yfov = 0.7;
    cam.perspective.znear = 0.05;
    cam.perspective.aspectRatio = 1.5;
    b.model.cameras.push_back(cam);
    tinygltf::Camera ortho;
    ortho.type = "orthographic";
    ortho.orthographic.xmag = ortho.orthographic.ymag = 1;
    ortho.orthographic.zfar = 10;
    ortho.orthographic.znear = 0.1;
    b.model.cameras.push_back(ortho);

    const int c = b.node("cam_node", -1);
    b.at(c).camera = 0;
    b.at(c).translation = {1, 2, 3};
    b.at(c).rotation = {0, kHalfSqrt2, 0, kHalfSqrt2};  // 90° about +y: x -> (0,0,-1), z -> (1,0,0)
    b.at(c).scale = {2, 2, 2};
    const int o = b.node("ortho_node", -1);
    b.at(o).camera = 1;
    b.scene({c, o, b.node("n", b.unit_triangle_mesh())});

    const Scene s = hemirad::scene::load(write(b.model, dir / "cam.gltf"));
    REQUIRE(s.cameras.size() == 1);
    const auto& k = s.cameras[0];
    CHECK(k.name == "view");
    CHECK(k.yfov == Approx(0.7));
    CHECK(k.aspect == Approx(1.5));
    CHECK(k.znear == Approx(0.05));
    CHECK(near(dvec3(k.camera_to_world[0]), dvec3(0, 0, -1)));
    CHECK(near(dvec3(k.camera_to_world[1]), dvec3(0, 1, 0)));
    CHECK(near(dvec3(k.camera_to_world[2]), dvec3(1, 0, 0)));
    CHECK(near(dvec3(k.camera_to_world[3]), dvec3(1, 2, 3)));
    CHECK(k.camera_to_world[3][3] == Approx(1.0));
    CHECK(count_warnings(s, "orthographic") == 1);
}

TEST_CASE("bad input is one line naming the file", "[scene]") {
    TempDir dir;
    ModelBuilder good;
    good.scene({good.node("n", good.unit_triangle_mesh())});

    SECTION("missing file") {
        check_rejected(dir / "absent.gltf", "cannot open");
    }
    SECTION("not a glTF extension") {
        std::ofstream(dir / "scene.obj") << "v 0 0 0\n";
        check_rejected(dir / "scene.obj", ".gltf or .glb");
    }
    SECTION("truncated JSON") {
        const fs::path file = write(good.model, dir / "cut.gltf");
        fs::resize_file(file, fs::file_size(file) / 2);
        check_rejected(file, "");
    }
    SECTION("asset version 1.0") {
        ModelBuilder b = good;
        b.model.asset.version = "1.0";
        check_rejected(write(b.model, dir / "v1.gltf"), "version '1.0'");
    }
    SECTION("index out of range") {
        ModelBuilder b;
        const int pos = b.positions({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
        const int idx = b.indices(std::vector<std::uint16_t>{0, 1, 5});
        b.scene({b.node("n", b.mesh("bad", {ModelBuilder::primitive(pos, idx)}))});
        check_rejected(write(b.model, dir / "idx.gltf"), "index 5 out of range");
    }
    SECTION("accessor past the end of its bufferView") {
        ModelBuilder b = good;
        b.model.accessors[0].count = 4;  // the view holds 3 positions
        check_rejected(write(b.model, dir / "short.gltf"), "run past the end");
    }
    SECTION("baseColorFactor component 1.5") {
        ModelBuilder b;
        const int m = b.material("hot", {1.5, 0.5, 0.5, 1.0});
        b.scene({b.node("n", b.unit_triangle_mesh("tri", m))});
        check_rejected(write(b.model, dir / "factor.gltf"), "material 'hot': baseColorFactor component 0 is 1.5");
    }
    SECTION("negative emissiveStrength") {
        ModelBuilder b;
        const int m = b.material("dark", {0.5, 0.5, 0.5, 1.0});
        tinygltf::Value::Object ext;
        ext["emissiveStrength"] = tinygltf::Value(-1.0);
        b.model.materials[m].extensions["KHR_materials_emissive_strength"] = tinygltf::Value(ext);
        b.scene({b.node("n", b.unit_triangle_mesh("tri", m))});
        check_rejected(write(b.model, dir / "strength.gltf"), "emissiveStrength");
    }
    SECTION("NaN position") {
        ModelBuilder b;
        const float nan = std::numeric_limits<float>::quiet_NaN();
        const int pos = b.positions({{0, 0, 0}, {1, nan, 0}, {0, 1, 0}});
        b.scene({b.node("n", b.mesh("m", {ModelBuilder::primitive(pos)}))});
        check_rejected(write(b.model, dir / "nan.gltf"), "position 1 is not finite");
    }
    SECTION("cycle in the node hierarchy") {
        ModelBuilder b = good;
        const int other = b.node("other", -1);
        b.at(0).children = {other};
        b.at(other).children = {0};
        check_rejected(write(b.model, dir / "loop.gltf"), "a cycle");
    }
    SECTION("node with two parents") {
        ModelBuilder b = good;
        const int p1 = b.node("p1", -1);
        const int p2 = b.node("p2", -1);
        b.at(p1).children = {0};
        b.at(p2).children = {0};
        b.scene({p1, p2});
        check_rejected(write(b.model, dir / "dag.gltf"), "node 0 has more than one parent");
    }
}

namespace {

// /proc/self/status's `field` ("VmRSS", "VmHWM": the peak), in kB; -1 where it cannot be read.
long memory_kb(const std::string& field) {
    std::ifstream status("/proc/self/status");
    for (std::string line; std::getline(status, line);)
        if (line.rfind(field + ":", 0) == 0) return std::stol(line.substr(field.size() + 1));
    return -1;
}

// Resets VmHWM to the current resident size (Linux 4.0 and later); false where that is refused.
bool reset_peak_memory() {
    std::ofstream clear("/proc/self/clear_refs");
    clear << "5";
    clear.close();
    return clear.good();
}

// `model` written as .gltf, then its JSON edited by `edit` (images, textures: what tinygltf's
// writer would try to encode itself).
fs::path write_edited(const tinygltf::Model& model, const fs::path& file,
                      const std::function<void(nlohmann::json&)>& edit) {
    write(model, file);
    std::ifstream in(file);
    nlohmann::json g = nlohmann::json::parse(in);
    in.close();
    edit(g);
    std::ofstream(file) << g.dump();
    return file;
}

}  // namespace

TEST_CASE("a 20000 x 20000 PNG texture decodes, a band of rows at a time, to its mean", "[scene][hostile]") {
    // tinygltf's stb refused it; OpenImageIO decodes it here with a few MB (grey, so that the
    // test writes and reads 400 MB of pixels rather than 1.2 GB).
    TempDir dir;
    constexpr int kSide = 20000;
    constexpr unsigned char kLevel = 200;
    {
        auto out = OIIO::ImageOutput::create("png");
        REQUIRE(out);
        OIIO::ImageSpec spec(kSide, kSide, 1, OIIO::TypeDesc::UINT8);
        spec.attribute("png:compressionLevel", 1);
        REQUIRE(out->open((dir / "big.png").string(), spec));
        const std::vector<unsigned char> row(kSide, kLevel);
        bool written = true;
        for (int y = 0; y < kSide && written; ++y) written = out->write_scanline(y, 0, OIIO::TypeDesc::UINT8, row.data());
        REQUIRE(written);
        REQUIRE(out->close());
    }
    ModelBuilder b;
    const int m = b.material("textured", {0.5, 1.0, 1.0, 1.0});
    b.scene({b.node("n", b.unit_triangle_mesh("tri", m))});
    const fs::path file = write_edited(b.model, dir / "big.gltf", [](nlohmann::json& g) {
        g["images"] = {{{"uri", "big.png"}}};
        g["textures"] = {{{"source", 0}}};
        g["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {{"index", 0}};
    });
    // The peak resident memory of the load, where Linux lets it be reset and read (stb needed
    // over 3 GB for this image: the whole image at 4 bytes a pixel, and its inflated rows).
    const bool measured = reset_peak_memory();
    const long before = memory_kb("VmRSS");
    const Scene s = hemirad::scene::load(file);
    const double linear = std::pow((kLevel / 255.0 + 0.055) / 1.055, 2.4);  // sRGB decoded
    CHECK(near(s.materials.at(0).base_color, dvec3(0.5 * linear, linear, linear), 1e-12));
    if (measured && before > 0) {
        CHECK(memory_kb("VmHWM") - before < 256 * 1024);
    } else {
        WARN("the peak resident memory cannot be reset here: not measured");
    }
}

TEST_CASE("an image's bufferView past the end of its buffer is refused, never read", "[scene][hostile]") {
    TempDir dir;
    ModelBuilder b;
    const int m = b.material("textured", {1.0, 1.0, 1.0, 1.0});
    b.scene({b.node("n", b.unit_triangle_mesh("tri", m))});
    const fs::path file = write_edited(b.model, dir / "past.gltf", [](nlohmann::json& g) {
        g["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", 0}, {"byteLength", 1 << 20}});
        g["images"] = {{{"bufferView", g["bufferViews"].size() - 1}, {"mimeType", "image/png"}}};
        g["textures"] = {{{"source", 0}}};
        g["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {{"index", 0}};
    });
    check_rejected(file, "runs past the end of buffer 0");
}

TEST_CASE("hostile files: deep JSON, an empty .glb, a FIFO, wrong .glb headers", "[scene][hostile]") {
    TempDir dir;
    ModelBuilder good;
    good.scene({good.node("n", good.unit_triangle_mesh())});
    SECTION("JSON nested 100,000 deep") {
        const fs::path file = write(good.model, dir / "deep.gltf");
        std::ifstream in(file);
        std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        in.close();
        text.insert(text.find('{') + 1, "\"extras\":" + std::string(100000, '{') + std::string(100000, '}') + ",");
        std::ofstream(file) << text;
        check_rejected(file, "nested more than 512 levels");
    }
    SECTION("an empty .glb") {
        std::ofstream(dir / "empty.glb").close();
        check_rejected(dir / "empty.glb", "empty");
    }
    SECTION("a FIFO") {
        REQUIRE(::mkfifo((dir / "fifo.gltf").c_str(), 0600) == 0);
        check_rejected(dir / "fifo.gltf", "is a FIFO, not a regular file");
    }
    SECTION("a texture's PNG cut short, and one under a JPEG's name") {
        {
            auto out = OIIO::ImageOutput::create("png");
            REQUIRE(out);
            const OIIO::ImageSpec spec(64, 64, 3, OIIO::TypeDesc::UINT8);
            std::vector<unsigned char> noise(64 * 64 * 3);
            std::mt19937 random(5);
            for (unsigned char& v : noise) v = static_cast<unsigned char>(random());  // incompressible
            REQUIRE(out->open((dir / "whole.png").string(), spec));
            REQUIRE(out->write_image(OIIO::TypeDesc::UINT8, noise.data()));
            REQUIRE(out->close());
        }
        std::ifstream in(dir / "whole.png", std::ios::binary);
        const std::string png((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        std::ofstream(dir / "cut.png", std::ios::binary) << png.substr(0, png.size() / 2);
        std::ofstream(dir / "named.jpg", std::ios::binary) << png;  // decoded as what it is
        ModelBuilder b;
        const int m = b.material("textured", {1.0, 1.0, 1.0, 1.0});
        b.scene({b.node("n", b.unit_triangle_mesh("tri", m))});
        for (const std::string uri : {"cut.png", "named.jpg"}) {
            const fs::path file = write_edited(b.model, dir / "t.gltf", [&](nlohmann::json& g) {
                g["images"] = {{{"uri", uri}}};
                g["textures"] = {{{"source", 0}}};
                g["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {{"index", 0}};
            });
            if (uri == "cut.png") {  // an error under --strict-textures, else a warning and the factors
                hemirad::scene::LoadOptions strict;
                strict.strict_textures = true;
                CHECK_THROWS_WITH(hemirad::scene::load(file, strict),
                                  Catch::Contains("image 0 'cut.png': the image does not decode past row"));
                const Scene s = hemirad::scene::load(file);
                CHECK(count_warnings(s, "image 0 'cut.png': the image does not decode past row") == 1);
                CHECK(s.materials.at(0).base_color == dvec3(1.0));
            } else {
                const Scene s = hemirad::scene::load(file);
                CHECK(s.materials.at(0).base_color.x > 0.1);  // the noise's mean, about 0.21 decoded
            }
        }
    }
    SECTION("a .glb cut short, and one whose JSON chunk runs past its end") {
        const fs::path file = write(good.model, dir / "good.glb");
        std::ifstream in(file, std::ios::binary);
        std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        in.close();
        std::ofstream(dir / "cut.glb", std::ios::binary) << bytes.substr(0, bytes.size() - 4);
        check_rejected(dir / "cut.glb", "truncated");
        bytes[12] = '\xff';  // the JSON chunk's length, far beyond the file
        bytes[13] = '\xff';
        std::ofstream(dir / "long_chunk.glb", std::ios::binary) << bytes;
        check_rejected(dir / "long_chunk.glb", "runs past");
        bytes.replace(12, 8, std::string("\x10\0\0\0BIN\0", 8));  // a first chunk that is not the JSON
        std::ofstream(dir / "bin_first.glb", std::ios::binary) << bytes;
        check_rejected(dir / "bin_first.glb", "first chunk of a .glb must be its JSON");
    }
}
