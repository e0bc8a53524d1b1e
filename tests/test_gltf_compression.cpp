// Compressed and quantized geometry: files written here with meshoptimizer's and Draco's encoders
// (the independent half of each codec) load as the plain files they encode, the bundled Cornell
// box among them, through a whole bake; KHR_mesh_quantization and sparse accessors against
// hand-computed positions; malformed compressed views refused with one line.
#include <draco/compression/encode.h>
#include <draco/mesh/triangle_soup_mesh_builder.h>
#include <meshoptimizer.h>
#include <tiny_gltf.h>

#include <algorithm>
#include <array>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "cli_support.h"
#include "core/error.h"
#include "scene/scene.h"
#include "test_scenes.h"

namespace {

using namespace hemirad::test;
using glm::dvec3;
using hemirad::scene::Scene;

void append(std::vector<unsigned char>& to, const void* bytes, std::size_t n) {
    while (to.size() % 4 != 0) to.push_back(0);
    const auto* p = static_cast<const unsigned char*>(bytes);
    to.insert(to.end(), p, p + n);
}

std::vector<unsigned char> encode_attributes(const unsigned char* data, std::size_t count, std::size_t stride) {
    std::vector<unsigned char> out(meshopt_encodeVertexBufferBound(count, stride));
    out.resize(meshopt_encodeVertexBuffer(out.data(), out.size(), data, count, stride));
    REQUIRE(!out.empty());
    return out;
}

// Indices of `size` bytes each, as TRIANGLES (meshopt_encodeIndexBuffer) or INDICES.
std::vector<unsigned char> encode_indices(const unsigned char* data, std::size_t count, std::size_t size,
                                          bool triangles) {
    std::vector<unsigned int> indices(count);
    for (std::size_t i = 0; i < count; ++i) {
        std::uint32_t v = 0;
        std::memcpy(&v, data + i * size, size);  // little-endian
        indices[i] = v;
    }
    unsigned int most = 0;
    for (unsigned int v : indices) most = std::max(most, v);
    std::vector<unsigned char> out(triangles ? meshopt_encodeIndexBufferBound(count, most + 1)
                                             : meshopt_encodeIndexSequenceBound(count, most + 1));
    out.resize(triangles ? meshopt_encodeIndexBuffer(out.data(), out.size(), indices.data(), count)
                         : meshopt_encodeIndexSequence(out.data(), out.size(), indices.data(), count));
    REQUIRE(!out.empty());
    return out;
}

// A .glb of `gltf` (its first buffer, without a uri, the BIN chunk `bin`).
std::vector<unsigned char> glb_of(const json& gltf, const std::vector<unsigned char>& bin) {
    std::string text = gltf.dump();
    text.resize((text.size() + 3) / 4 * 4, ' ');
    std::vector<unsigned char> chunk = bin;
    chunk.resize((chunk.size() + 3) / 4 * 4, 0);
    std::vector<unsigned char> out;
    const auto u32 = [&](std::uint32_t v) {
        for (int i = 0; i < 4; ++i) out.push_back(static_cast<unsigned char>(v >> (8 * i)));
    };
    u32(0x46546C67);
    u32(2);
    u32(static_cast<std::uint32_t>(12 + 8 + text.size() + 8 + chunk.size()));
    u32(static_cast<std::uint32_t>(text.size()));
    u32(0x4E4F534A);
    out.insert(out.end(), text.begin(), text.end());
    u32(static_cast<std::uint32_t>(chunk.size()));
    u32(0x004E4942);
    out.insert(out.end(), chunk.begin(), chunk.end());
    return out;
}

void write_bytes(const fs::path& file, const std::vector<unsigned char>& bytes) {
    std::ofstream out(file, std::ios::binary);
    out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
    REQUIRE(out.good());
}

// The bundled Cornell box with every bufferView compressed: vertex views as ATTRIBUTES, index
// views alternately as TRIANGLES and INDICES, the compressed bytes in `compressed` (buffer 0)
// and the plain bytes only in a fallback buffer without a uri (buffer 1).
json meshopt_cornell(std::vector<unsigned char>& compressed) {
    tinygltf::TinyGLTF loader;
    tinygltf::Model plain;
    std::string err, warn;
    REQUIRE(loader.LoadASCIIFromFile(&plain, &err, &warn, kCornellBox.string()));
    json gltf = read_json(kCornellBox);
    const std::vector<unsigned char>& bytes = plain.buffers.at(0).data;
    int index_views = 0;
    for (std::size_t v = 0; v < gltf["bufferViews"].size(); ++v) {
        json& view = gltf["bufferViews"][v];
        REQUIRE(view["buffer"] == 0);
        const std::size_t offset = view.value("byteOffset", 0), length = view["byteLength"];
        // The accessor that reads the view says what its elements are.
        std::size_t element = 0;
        for (const json& a : gltf["accessors"])
            if (a["bufferView"] == v)
                element = (a["componentType"] == 5123 ? 2 : 4) * (a["type"] == "VEC3" ? 3 : a["type"] == "VEC2" ? 2 : 1);
        REQUIRE(element > 0);
        const bool indices = view.value("target", 0) == 34963;
        const bool triangles = indices && index_views++ % 2 == 0;
        const std::vector<unsigned char> packed =
            indices ? encode_indices(bytes.data() + offset, length / element, element, triangles)
                    : encode_attributes(bytes.data() + offset, length / element, element);
        append(compressed, nullptr, 0);
        const std::size_t at = compressed.size();
        append(compressed, packed.data(), packed.size());
        view["buffer"] = 1;
        if (!indices) view["byteStride"] = element;
        view["extensions"]["EXT_meshopt_compression"] = {
            {"buffer", 0},         {"byteOffset", at}, {"byteLength", packed.size()},
            {"byteStride", element}, {"count", length / element},
            {"mode", indices ? (triangles ? "TRIANGLES" : "INDICES") : "ATTRIBUTES"}};
    }
    gltf["buffers"] = json::array(
        {{{"byteLength", compressed.size()}},
         {{"byteLength", bytes.size()}, {"extensions", {{"EXT_meshopt_compression", {{"fallback", true}}}}}}});
    gltf["extensionsUsed"] = {"EXT_meshopt_compression"};
    gltf["extensionsRequired"] = {"EXT_meshopt_compression"};
    return gltf;
}

// The bundled Cornell box with each primitive's triangles in KHR_draco_mesh_compression (one
// Draco mesh a primitive, positions at `bits` of quantization, 0 for none), its accessors left
// without bufferViews, the Draco data in buffer 0.
json draco_cornell(std::vector<unsigned char>& bin, int bits) {
    tinygltf::TinyGLTF loader;
    tinygltf::Model plain;
    std::string err, warn;
    REQUIRE(loader.LoadASCIIFromFile(&plain, &err, &warn, kCornellBox.string()));
    json gltf = read_json(kCornellBox);
    json views = json::array();
    for (std::size_t m = 0; m < plain.meshes.size(); ++m)
        for (std::size_t p = 0; p < plain.meshes[m].primitives.size(); ++p) {
            const tinygltf::Primitive& prim = plain.meshes[m].primitives[p];
            const auto bytes_of = [&](int accessor) {
                const tinygltf::Accessor& a = plain.accessors[std::size_t(accessor)];
                const tinygltf::BufferView& v = plain.bufferViews[std::size_t(a.bufferView)];
                return plain.buffers[0].data.data() + v.byteOffset + a.byteOffset;
            };
            const tinygltf::Accessor& index_accessor = plain.accessors[std::size_t(prim.indices)];
            REQUIRE(index_accessor.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT);
            const auto* positions = reinterpret_cast<const float*>(bytes_of(prim.attributes.at("POSITION")));
            const auto* indices = reinterpret_cast<const std::uint16_t*>(bytes_of(prim.indices));
            const int faces = int(index_accessor.count / 3);
            draco::TriangleSoupMeshBuilder builder;
            builder.Start(faces);
            const int position = builder.AddAttribute(draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32);
            for (int f = 0; f < faces; ++f)
                builder.SetAttributeValuesForFace(position, draco::FaceIndex(f), positions + 3 * indices[3 * f],
                                                  positions + 3 * indices[3 * f + 1], positions + 3 * indices[3 * f + 2]);
            const std::unique_ptr<draco::Mesh> mesh = builder.Finalize();
            REQUIRE(mesh != nullptr);
            draco::Encoder encoder;
            if (bits > 0) encoder.SetAttributeQuantization(draco::GeometryAttribute::POSITION, bits);
            draco::EncoderBuffer encoded;
            REQUIRE(encoder.EncodeMeshToBuffer(*mesh, &encoded).ok());
            append(bin, nullptr, 0);
            views.push_back({{"buffer", 0}, {"byteOffset", bin.size()}, {"byteLength", encoded.size()}});
            append(bin, encoded.data(), encoded.size());
            json& primitive = gltf["meshes"][m]["primitives"][p];
            primitive["extensions"]["KHR_draco_mesh_compression"] = {
                {"bufferView", views.size() - 1},
                {"attributes", {{"POSITION", mesh->attribute(position)->unique_id()}}}};
            for (const int accessor : {prim.attributes.at("POSITION"), prim.indices})
                gltf["accessors"][std::size_t(accessor)].erase("bufferView");
        }
    gltf["bufferViews"] = views;
    gltf["buffers"] = json::array({{{"byteLength", bin.size()}, {"uri", "draco.bin"}}});
    gltf["extensionsUsed"] = {"KHR_draco_mesh_compression"};
    gltf["extensionsRequired"] = {"KHR_draco_mesh_compression"};
    return gltf;
}

// A scene's triangles as a sorted list, each starting at its least vertex (its winding kept):
// Draco may reorder a mesh's faces and the corners of each.
std::vector<std::array<dvec3, 3>> triangle_set(const Scene& scene) {
    const auto less = [](const dvec3& a, const dvec3& b) {
        return std::lexicographical_compare(&a.x, &a.x + 3, &b.x, &b.x + 3);
    };
    std::vector<std::array<dvec3, 3>> out;
    for (const hemirad::scene::Triangle& t : scene.triangles) {
        std::array<dvec3, 3> p = t.p;
        while (less(p[1], p[0]) || less(p[2], p[0])) std::rotate(p.begin(), p.begin() + 1, p.end());
        out.push_back(p);
    }
    std::sort(out.begin(), out.end(), [&](const auto& a, const auto& b) {
        return std::lexicographical_compare(a.begin(), a.end(), b.begin(), b.end(), less);
    });
    return out;
}

void check_same_triangles(const Scene& got, const Scene& want) {
    REQUIRE(got.triangles.size() == want.triangles.size());
    for (std::size_t t = 0; t < want.triangles.size(); ++t)
        for (int k = 0; k < 3; ++k) {
            INFO("triangle " << t << " vertex " << k);
            CHECK(got.triangles[t].p[std::size_t(k)] == want.triangles[t].p[std::size_t(k)]);
            CHECK(got.triangles[t].rho[std::size_t(k)] == want.triangles[t].rho[std::size_t(k)]);
            CHECK(got.triangles[t].material == want.triangles[t].material);
        }
}

// A one-triangle-per-cell grid of `n` x `n` vertices in one primitive (plain floats, 32-bit
// indices), as JSON and its buffer, for the tests that change one accessor.
struct Grid {
    std::vector<float> positions;
    std::vector<std::uint32_t> indices;
    explicit Grid(int n) {
        for (int j = 0; j < n; ++j)
            for (int i = 0; i < n; ++i) {
                positions.push_back(float(i) * 0.25f);
                positions.push_back(0.1f * float((i * 7 + j * 3) % 5));  // bumpy, so no two are alike
                positions.push_back(float(j) * 0.25f);
            }
        for (int j = 0; j + 1 < n; ++j)
            for (int i = 0; i + 1 < n; ++i) {
                const std::uint32_t a = std::uint32_t(j * n + i);
                for (std::uint32_t v : {a, a + std::uint32_t(n), a + 1, a + 1, a + std::uint32_t(n), a + std::uint32_t(n) + 1})
                    indices.push_back(v);
            }
    }
    std::size_t vertices() const { return positions.size() / 3; }
    // `gltf` and its buffer written to grid.gltf and grid.bin in `dir`, then loaded: every
    // cell's two triangles there.
    Scene load(const TempDir& dir, const json& gltf, const std::vector<unsigned char>& bin) const {
        write_json(dir / "grid.gltf", gltf);
        write_bytes(dir / "grid.bin", bin);
        Scene scene = hemirad::scene::load(dir / "grid.gltf");
        REQUIRE(scene.triangles.size() == indices.size() / 3);
        return scene;
    }
    // A glTF of the grid with the positions accessor `position` (its bufferViews and buffer
    // bytes appended by the caller); indices plain in buffer 0.
    json gltf(std::vector<unsigned char>& bin, const json& position_accessor, json views) const {
        append(bin, nullptr, 0);
        const std::size_t at = bin.size();
        append(bin, indices.data(), indices.size() * 4);
        views.push_back({{"buffer", 0}, {"byteOffset", at}, {"byteLength", indices.size() * 4}});
        const std::size_t index_view = views.size() - 1;
        return {{"asset", {{"version", "2.0"}}},
                {"scene", 0},
                {"scenes", {{{"nodes", {0}}}}},
                {"nodes", {{{"name", "grid"}, {"mesh", 0}}}},
                {"meshes", {{{"primitives", {{{"attributes", {{"POSITION", 0}}}, {"indices", 1}}}}}}},
                {"accessors",
                 {position_accessor,
                  {{"bufferView", index_view}, {"componentType", 5125}, {"count", indices.size()}, {"type", "SCALAR"}}}},
                {"bufferViews", views},
                {"buffers", {{{"byteLength", bin.size()}, {"uri", "grid.bin"}}}}};
    }
};

}  // namespace

TEST_CASE("EXT_meshopt_compression: the Cornell box compressed loads and bakes as the plain one",
          "[scene][meshopt]") {
    TempDir dir;
    std::vector<unsigned char> compressed;
    json gltf = meshopt_cornell(compressed);
    json as_gltf = gltf;
    as_gltf["buffers"][0]["uri"] = "cornell.bin";
    write_json(dir / "cornell.gltf", as_gltf);
    write_bytes(dir / "cornell.bin", compressed);
    write_bytes(dir / "cornell.glb", glb_of(gltf, compressed));

    const Scene want = hemirad::scene::load(kCornellBox);
    REQUIRE(want.triangles.size() == 32);
    check_same_triangles(hemirad::scene::load(dir / "cornell.gltf"), want);
    check_same_triangles(hemirad::scene::load(dir / "cornell.glb"), want);

    // The whole bake, as a user runs it on the compressed file: the same light everywhere.
    const json plain = bake_ok(dir, kCornellBox, dir / "plain");
    const json packed = bake_ok(dir, dir / "cornell.glb", dir / "packed");
    CHECK(packed["counts"] == plain["counts"]);
    CHECK(packed["meshes"] == plain["meshes"]);
    CHECK(read_text(dir / "packed" / "baked.bin") == read_text(dir / "plain" / "baked.bin"));
}

TEST_CASE("EXT_meshopt_compression: EXPONENTIAL-filtered positions decode within the filter's precision",
          "[scene][meshopt]") {
    TempDir dir;
    const Grid grid(9);
    constexpr int kBits = 15;  // mantissa bits per component
    std::vector<std::uint32_t> filtered(grid.positions.size());
    meshopt_encodeFilterExp(filtered.data(), grid.vertices(), 12, kBits, grid.positions.data());
    const std::vector<unsigned char> packed =
        encode_attributes(reinterpret_cast<const unsigned char*>(filtered.data()), grid.vertices(), 12);
    std::vector<unsigned char> bin;
    append(bin, packed.data(), packed.size());
    json views = json::array({{{"buffer", 1},
                               {"byteLength", grid.vertices() * 12},
                               {"byteStride", 12},
                               {"extensions",
                                {{"EXT_meshopt_compression",
                                  {{"buffer", 0}, {"byteLength", packed.size()}, {"byteStride", 12},
                                   {"count", grid.vertices()}, {"mode", "ATTRIBUTES"}, {"filter", "EXPONENTIAL"}}}}}}});
    json gltf = grid.gltf(bin, {{"bufferView", 0}, {"componentType", 5126}, {"count", grid.vertices()}, {"type", "VEC3"}},
                          views);
    gltf["buffers"].push_back(
        {{"byteLength", grid.vertices() * 12}, {"extensions", {{"EXT_meshopt_compression", {{"fallback", true}}}}}});
    gltf["extensionsRequired"] = {"EXT_meshopt_compression"};
    const Scene got = grid.load(dir, gltf, bin);
    for (std::size_t t = 0; t < got.triangles.size(); ++t)
        for (std::size_t k = 0; k < 3; ++k) {
            const std::uint32_t v = grid.indices[3 * t + k];
            double largest = 0.0;
            for (int c = 0; c < 3; ++c) largest = std::max(largest, double(std::abs(grid.positions[3 * v + std::size_t(c)])));
            for (int c = 0; c < 3; ++c) {
                const double want = grid.positions[3 * v + std::size_t(c)];
                // A 15-bit signed mantissa under one exponent per vertex, chosen for its largest
                // component: a step of at most 2^-13 of that, half a step of error.
                CHECK(std::abs(got.triangles[t].p[k][c] - want) <= std::ldexp(largest, -(kBits - 1)));
            }
        }
}

TEST_CASE("KHR_mesh_quantization: byte and short positions, normalized or not, under the node's transform",
          "[scene][quantization]") {
    TempDir dir;
    const Grid grid(5);
    // Shorts normalized to [-1, 1] (padded to 8 bytes a vertex, as glTF aligns them), scaled
    // back by the node; and unsigned bytes as plain integers.
    std::vector<std::int16_t> shorts;
    std::vector<std::uint8_t> bytes;
    for (std::size_t v = 0; v < grid.vertices(); ++v) {
        for (int c = 0; c < 3; ++c) {
            shorts.push_back(static_cast<std::int16_t>(std::lround(grid.positions[3 * v + std::size_t(c)] / 2.0 * 32767.0)));
            bytes.push_back(static_cast<std::uint8_t>(std::lround(grid.positions[3 * v + std::size_t(c)] * 20.0)));
        }
        shorts.push_back(0);
        bytes.push_back(0);
    }
    SECTION("normalized shorts") {
        std::vector<unsigned char> bin;
        append(bin, shorts.data(), shorts.size() * 2);
        json gltf = grid.gltf(bin,
                              {{"bufferView", 0}, {"componentType", 5122}, {"normalized", true},
                               {"count", grid.vertices()}, {"type", "VEC3"}},
                              json::array({{{"buffer", 0}, {"byteLength", shorts.size() * 2}, {"byteStride", 8}}}));
        gltf["nodes"][0]["scale"] = {2.0, 2.0, 2.0};
        gltf["nodes"][0]["translation"] = {1.0, 0.0, -1.0};
        gltf["extensionsRequired"] = {"KHR_mesh_quantization"};
        const Scene got = grid.load(dir, gltf, bin);
        for (std::size_t t = 0; t < got.triangles.size(); ++t)
            for (std::size_t k = 0; k < 3; ++k) {
                const std::uint32_t v = grid.indices[3 * t + k];
                const dvec3 q(shorts[4 * v], shorts[4 * v + 1], shorts[4 * v + 2]);
                const dvec3 want = q / 32767.0 * 2.0 + dvec3(1.0, 0.0, -1.0);
                CHECK(glm::length(got.triangles[t].p[k] - want) < 1e-12);
                // And the grid itself, within the quantization step.
                CHECK(std::abs(got.triangles[t].p[k].x - 1.0 - grid.positions[3 * v]) <= 2.0 / 32767.0);
            }
    }
    SECTION("unsigned bytes, not normalized") {
        std::vector<unsigned char> bin;
        append(bin, bytes.data(), bytes.size());
        json gltf = grid.gltf(
            bin, {{"bufferView", 0}, {"componentType", 5121}, {"count", grid.vertices()}, {"type", "VEC3"}},
            json::array({{{"buffer", 0}, {"byteLength", bytes.size()}, {"byteStride", 4}}}));
        gltf["nodes"][0]["scale"] = {0.05, 0.05, 0.05};
        const Scene got = grid.load(dir, gltf, bin);
        const std::uint32_t v = grid.indices[5];  // triangle 1, vertex 2
        CHECK(glm::length(got.triangles[1].p[2] - dvec3(bytes[4 * v], bytes[4 * v + 1], bytes[4 * v + 2]) * 0.05) <
              1e-12);
    }
}

TEST_CASE("a required extension the loader does not read is named in a warning", "[scene]") {
    TempDir dir;
    const Grid grid(3);
    std::vector<unsigned char> bin;
    append(bin, grid.positions.data(), grid.positions.size() * 4);
    json gltf = grid.gltf(bin, {{"bufferView", 0}, {"componentType", 5126}, {"count", grid.vertices()}, {"type", "VEC3"}},
                          json::array({{{"buffer", 0}, {"byteLength", grid.positions.size() * 4}}}));
    gltf["extensionsUsed"] = {"KHR_mesh_quantization", "EXT_made_up"};
    gltf["extensionsRequired"] = {"KHR_mesh_quantization", "EXT_made_up"};
    const Scene got = grid.load(dir, gltf, bin);
    std::vector<std::string> named;
    for (const std::string& w : got.warnings)
        if (w.find("required extension") != std::string::npos) named.push_back(w);
    REQUIRE(named.size() == 1);
    CHECK(named[0] == (dir / "grid.gltf").string() +
                          ": required extension EXT_made_up is not supported; the scene is read without it");
}

TEST_CASE("sparse accessors: values written over a bufferView's elements, or over zeros", "[scene][sparse]") {
    TempDir dir;
    const Grid grid(4);
    const std::vector<std::uint16_t> which = {2, 9};
    const std::vector<float> values = {5.0f, 6.0f, 7.0f, -1.0f, -2.0f, -3.0f};
    for (const bool over_zeros : {false, true}) {
        DYNAMIC_SECTION((over_zeros ? "over zeros" : "over a bufferView")) {
            std::vector<unsigned char> bin;
            append(bin, grid.positions.data(), grid.positions.size() * 4);
            const std::size_t which_at = (bin.size() + 3) / 4 * 4;
            append(bin, which.data(), which.size() * 2);
            const std::size_t values_at = (bin.size() + 3) / 4 * 4;
            append(bin, values.data(), values.size() * 4);
            json views = json::array({{{"buffer", 0}, {"byteLength", grid.positions.size() * 4}},
                                      {{"buffer", 0}, {"byteOffset", which_at}, {"byteLength", which.size() * 2}},
                                      {{"buffer", 0}, {"byteOffset", values_at}, {"byteLength", values.size() * 4}}});
            json accessor = {{"componentType", 5126},
                             {"count", grid.vertices()},
                             {"type", "VEC3"},
                             {"sparse",
                              {{"count", 2},
                               {"indices", {{"bufferView", 1}, {"componentType", 5123}}},
                               {"values", {{"bufferView", 2}}}}}};
            if (!over_zeros) accessor["bufferView"] = 0;
            const Scene got = grid.load(dir, grid.gltf(bin, accessor, views), bin);
            for (std::size_t t = 0; t < got.triangles.size(); ++t)
                for (std::size_t k = 0; k < 3; ++k) {
                    const std::uint32_t v = grid.indices[3 * t + k];
                    dvec3 want = over_zeros ? dvec3(0.0)
                                            : dvec3(grid.positions[3 * v], grid.positions[3 * v + 1],
                                                    grid.positions[3 * v + 2]);
                    for (std::size_t s = 0; s < which.size(); ++s)
                        if (which[s] == v) want = dvec3(values[3 * s], values[3 * s + 1], values[3 * s + 2]);
                    CHECK(got.triangles[t].p[k] == want);
                }
        }
    }
}

TEST_CASE("malformed EXT_meshopt_compression views are one line naming the file and the bufferView",
          "[scene][meshopt][hostile]") {
    TempDir dir;
    std::vector<unsigned char> compressed;
    const json good = meshopt_cornell(compressed);
    const auto refused = [&](const std::string& problem, const std::function<void(json&, std::vector<unsigned char>&)>& edit) {
        json gltf = good;
        std::vector<unsigned char> bin = compressed;
        edit(gltf, bin);
        gltf["buffers"][0]["uri"] = "bad.bin";
        gltf["buffers"][0]["byteLength"] = bin.size();
        write_json(dir / "bad.gltf", gltf);
        write_bytes(dir / "bad.bin", bin);
        const std::string message = load_error(dir / "bad.gltf");
        INFO(message);
        CHECK(message.rfind((dir / "bad.gltf").string() + ": bufferView ", 0) == 0);
        CHECK(message.find("(EXT_meshopt_compression)") != std::string::npos);
        CHECK(message.find(problem) != std::string::npos);
        CHECK(message.find('\n') == std::string::npos);
    };
    const auto ext = [](json& gltf, int view) -> json& {
        return gltf["bufferViews"][std::size_t(view)]["extensions"]["EXT_meshopt_compression"];
    };
    refused("do not decode", [&](json& g, std::vector<unsigned char>& bin) {
        const std::size_t at = ext(g, 0)["byteOffset"];
        for (std::size_t i = at; i < at + 8; ++i) bin[i] = 0xff;  // a header byte no encoder writes
    });
    refused("do not decode", [&](json& g, std::vector<unsigned char>&) { ext(g, 1)["byteLength"] = 2; });
    refused("run past the end of buffer 0", [&](json& g, std::vector<unsigned char>& bin) {
        ext(g, 0)["byteLength"] = bin.size() + 1;
    });
    refused("unknown mode 'POINTS'", [&](json& g, std::vector<unsigned char>&) { ext(g, 0)["mode"] = "POINTS"; });
    refused("unknown filter 'SPHERICAL'", [&](json& g, std::vector<unsigned char>&) { ext(g, 0)["filter"] = "SPHERICAL"; });
    refused("multiple of 4", [&](json& g, std::vector<unsigned char>&) { ext(g, 0)["byteStride"] = 6; });
    refused("do not fit its byteLength", [&](json& g, std::vector<unsigned char>&) { ext(g, 0)["count"] = 1000; });
    refused("count is missing", [&](json& g, std::vector<unsigned char>&) { ext(g, 0).erase("count"); });
    refused("count divisible by 3", [&](json& g, std::vector<unsigned char>&) {
        for (std::size_t v = 0; v < g["bufferViews"].size(); ++v)
            if (ext(g, int(v))["mode"] == "TRIANGLES") {
                ext(g, int(v))["count"] = 4;
                break;
            }
    });

    // A fallback buffer declared huge, with a view far into it: refused before it is made.
    {
        json gltf = good;
        gltf["buffers"][0]["uri"] = "bad.bin";
        gltf["buffers"][1]["byteLength"] = std::uint64_t{1} << 40;
        gltf["bufferViews"][0]["byteOffset"] = std::uint64_t{1} << 39;
        write_json(dir / "huge.gltf", gltf);
        write_bytes(dir / "bad.bin", compressed);
        const std::string message = load_error(dir / "huge.gltf");
        INFO(message);
        CHECK(message.rfind((dir / "huge.gltf").string() + ": buffer 1 (EXT_meshopt_compression fallback)", 0) == 0);
        CHECK(message.find("above the limit") != std::string::npos);
    }

    // From the command line: exit 2, one line, nothing written.
    json gltf = good;
    std::vector<unsigned char> bin = compressed;
    bin[std::size_t(ext(gltf, 0)["byteOffset"])] = 0xff;
    write_bytes(dir / "bad.glb", glb_of(gltf, bin));
    const RunResult r = run_hemirad(dir, bake_args(dir / "bad.glb", dir / "out"));
    CHECK(r.code == 2);
    CHECK(r.err.find("bad.glb: bufferView 0 (EXT_meshopt_compression)") != std::string::npos);
    CHECK(!fs::exists(dir / "out"));
}

TEST_CASE("KHR_draco_mesh_compression: the Cornell box compressed loads as the plain one and bakes alike",
          "[scene][draco]") {
    TempDir dir;
    const Scene want = hemirad::scene::load(kCornellBox);
    const std::vector<std::array<dvec3, 3>> want_set = triangle_set(want);
    SECTION("lossless") {
        std::vector<unsigned char> bin;
        write_json(dir / "draco.gltf", draco_cornell(bin, 0));
        write_bytes(dir / "draco.bin", bin);
        const Scene got = hemirad::scene::load(dir / "draco.gltf");
        CHECK(triangle_set(got) == want_set);
        // Each node's triangles stay its own, with its material.
        REQUIRE(got.triangles.size() == want.triangles.size());
        for (std::size_t t = 0; t < got.triangles.size(); ++t) {
            CHECK(got.triangles[t].node == want.triangles[t].node);
            CHECK(got.triangles[t].material == want.triangles[t].material);
        }
        // The user's path: the same light on every mesh, within what a different triangle order
        // moves it (the meshes' patches and elements are the same surfaces, numbered otherwise).
        const json plain = bake_ok(dir, kCornellBox, dir / "plain");
        const json packed = bake_ok(dir, dir / "draco.gltf", dir / "packed");
        REQUIRE(packed["meshes"].size() == plain["meshes"].size());
        for (std::size_t m = 0; m < plain["meshes"].size(); ++m)
            for (int c = 0; c < 3; ++c) {
                const double a = packed["meshes"][m]["radiosity"][c], b = plain["meshes"][m]["radiosity"][c];
                INFO(plain["meshes"][m]["name"] << " channel " << c);
                CHECK(std::abs(a - b) <= 0.02 * b + 1e-9);
            }
    }
    SECTION("positions quantized to 14 bits") {
        std::vector<unsigned char> bin;
        write_json(dir / "draco.gltf", draco_cornell(bin, 14));
        write_bytes(dir / "draco.bin", bin);
        const std::vector<std::array<dvec3, 3>> got = triangle_set(hemirad::scene::load(dir / "draco.gltf"));
        REQUIRE(got.size() == want_set.size());
        // 14 bits over each primitive's extent (at most the box's 0.56 m): within 0.56 / 2^14.
        for (std::size_t t = 0; t < got.size(); ++t)
            for (std::size_t k = 0; k < 3; ++k) CHECK(glm::length(got[t][k] - want_set[t][k]) <= 1e-4);
    }
    SECTION("data that does not decode") {
        std::vector<unsigned char> bin;
        const json gltf = draco_cornell(bin, 0);
        std::fill(bin.begin() + 8, bin.begin() + 24, 0xff);  // the first primitive's header and more
        write_json(dir / "draco.gltf", gltf);
        write_bytes(dir / "draco.bin", bin);
        const std::string message = load_error(dir / "draco.gltf");
        INFO(message);
        CHECK(message.rfind((dir / "draco.gltf").string() + ": mesh 'floor' primitive 0 (KHR_draco_mesh_compression)", 0) ==
              0);
        CHECK(message.find("does not decode") != std::string::npos);
        CHECK(message.find('\n') == std::string::npos);
    }
}
