// `hemirad bench --accuracy`, the image part (see bench_image.h).
#include "cli/bench_image.h"

#include <fmt/core.h>
#include <tiny_gltf.h>

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>

#include <glm/glm.hpp>

#include "cli/bake.h"
#include "cli/bench_support.h"
#include "core/error.h"

namespace hemirad::cli {
namespace fs = std::filesystem;
using ordered_json = nlohmann::ordered_json;

namespace {

constexpr int kTile = 16;

double luminance(double r, double g, double b) { return 0.2126 * r + 0.7152 * g + 0.0722 * b; }
double luminance(const glm::dvec3& c) { return luminance(c.x, c.y, c.z); }

glm::dvec3 vec3(const ordered_json& j) { return {j.at(0).get<double>(), j.at(1).get<double>(), j.at(2).get<double>()}; }

// Linear RGB of an image file (render.exr), as floats.
std::vector<float> read_rgb(const fs::path& file, int& width, int& height) {
    auto in = OIIO::ImageInput::open(file.string());
    if (!in) throw InputError(fmt::format("{}: cannot read the image", file.string()));
    const OIIO::ImageSpec& spec = in->spec();
    if (spec.nchannels < 3) throw InputError(fmt::format("{}: fewer than 3 channels", file.string()));
    width = spec.width;
    height = spec.height;
    std::vector<float> all(std::size_t(width) * height * spec.nchannels);
    if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, all.data()))
        throw InputError(fmt::format("{}: cannot read the image", file.string()));
    std::vector<float> rgb(std::size_t(width) * height * 3);
    for (std::size_t p = 0; p < std::size_t(width) * height; ++p)
        for (int c = 0; c < 3; ++c) rgb[3 * p + c] = all[p * spec.nchannels + c];
    return rgb;
}

// A float VEC3 or an index accessor of a file hemirad wrote (tightly packed or strided).
std::vector<glm::dvec3> read_vec3(const tinygltf::Model& m, int accessor) {
    const tinygltf::Accessor& a = m.accessors.at(accessor);
    const tinygltf::BufferView& v = m.bufferViews.at(a.bufferView);
    if (a.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT || a.type != TINYGLTF_TYPE_VEC3)
        throw InputError("baked glTF: an attribute is not float VEC3");
    const std::size_t stride = v.byteStride ? v.byteStride : 12;
    const unsigned char* base = m.buffers.at(v.buffer).data.data() + v.byteOffset + a.byteOffset;
    if (v.byteOffset + a.byteOffset + (a.count ? (a.count - 1) * stride + 12 : 0) > m.buffers.at(v.buffer).data.size())
        throw InputError("baked glTF: an accessor runs past its buffer");
    std::vector<glm::dvec3> out(a.count);
    for (std::size_t i = 0; i < a.count; ++i) {
        float f[3];
        std::memcpy(f, base + i * stride, 12);
        out[i] = glm::dvec3(f[0], f[1], f[2]);
    }
    return out;
}

std::vector<std::uint32_t> read_indices(const tinygltf::Model& m, int accessor, std::size_t vertices) {
    std::vector<std::uint32_t> out;
    if (accessor < 0) {
        for (std::size_t i = 0; i < vertices; ++i) out.push_back(std::uint32_t(i));
        return out;
    }
    const tinygltf::Accessor& a = m.accessors.at(accessor);
    const tinygltf::BufferView& v = m.bufferViews.at(a.bufferView);
    const int size = tinygltf::GetComponentSizeInBytes(a.componentType);
    if (size != 1 && size != 2 && size != 4) throw InputError("baked glTF: bad index type");
    const unsigned char* base = m.buffers.at(v.buffer).data.data() + v.byteOffset + a.byteOffset;
    if (v.byteOffset + a.byteOffset + a.count * size > m.buffers.at(v.buffer).data.size())
        throw InputError("baked glTF: an accessor runs past its buffer");
    for (std::size_t i = 0; i < a.count; ++i) {
        std::uint32_t x = 0;
        std::memcpy(&x, base + i * size, size);  // little-endian
        if (x >= vertices) throw InputError("baked glTF: an index out of range");
        out.push_back(x);
    }
    return out;
}

struct Run {
    std::string label, quality;
    int hemicube = 0;
    double element_size = 0.0;
};

}  // namespace

ImageReference load_image_reference(const std::string& dir) {
    ImageReference r;
    const fs::path exr = fs::path(dir) / "reference.exr", json = fs::path(dir) / "reference.json";
    {
        std::ifstream in(json);
        if (!in) throw InputError(fmt::format("{}: not found (run bench --accuracy from the repository root)", json.string()));
        try {
            r.json = ordered_json::parse(in);
        } catch (const nlohmann::json::exception& e) {
            throw InputError(fmt::format("{}: not JSON: {}", json.string(), e.what()));
        }
        if (!r.json.contains("faces")) throw InputError(fmt::format("{}: not a path-traced reference", json.string()));
    }
    auto in = OIIO::ImageInput::open(exr.string());
    if (!in) throw InputError(fmt::format("{}: cannot read the image", exr.string()));
    const OIIO::ImageSpec& spec = in->spec();
    const std::vector<std::string> want = {"R", "G", "B", "noise.Y", "face"};
    if (spec.nchannels != int(want.size())) throw InputError(fmt::format("{}: not a path-traced reference", exr.string()));
    std::vector<int> index(want.size());
    for (std::size_t k = 0; k < want.size(); ++k) {
        index[k] = spec.channelindex(want[k]);
        if (index[k] < 0) throw InputError(fmt::format("{}: no channel {}", exr.string(), want[k]));
    }
    r.width = spec.width;
    r.height = spec.height;
    std::vector<float> all(std::size_t(r.width) * r.height * spec.nchannels);
    if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, all.data()))
        throw InputError(fmt::format("{}: cannot read the image", exr.string()));
    const std::size_t n = std::size_t(r.width) * r.height;
    r.rgb.resize(3 * n);
    r.noise_y.resize(n);
    r.face.resize(n);
    for (std::size_t p = 0; p < n; ++p) {
        const float* px = &all[p * spec.nchannels];
        for (int c = 0; c < 3; ++c) r.rgb[3 * p + c] = px[index[c]];
        r.noise_y[p] = px[index[3]];
        r.face[p] = int(std::lround(px[index[4]]));
    }
    return r;
}

PixelErrors compare_pixels(const std::vector<float>& rgb, int width, int height, const ImageReference& ref) {
    if (width != ref.width || height != ref.height || rgb.size() != std::size_t(width) * height * 3)
        throw InternalError(fmt::format("bench --accuracy: a {}x{} image against a {}x{} reference", width, height,
                                        ref.width, ref.height));
    const ordered_json& faces = ref.json.at("faces");
    std::vector<bool> emitter(faces.size());
    for (std::size_t f = 0; f < faces.size(); ++f) emitter[f] = faces[f].at("emitter").get<bool>();
    PixelErrors out;
    double e2 = 0.0, s2 = 0.0, sum = 0.0;
    const int tiles_x = (width + kTile - 1) / kTile, tiles_y = (height + kTile - 1) / kTile;
    std::vector<double> tile_sum(std::size_t(tiles_x) * tiles_y, 0.0);
    std::vector<long> tile_count(tile_sum.size(), 0);
    for (int y = 0; y < height; ++y) {
        for (int x = 0; x < width; ++x) {
            const std::size_t p = std::size_t(y) * width + x;
            const int f = ref.face[p];
            if (f < 0 || std::size_t(f) >= faces.size() || emitter[f]) continue;
            const double r = luminance(ref.rgb[3 * p], ref.rgb[3 * p + 1], ref.rgb[3 * p + 2]);
            if (!(r > 0.0)) continue;
            const double h = luminance(rgb[3 * p], rgb[3 * p + 1], rgb[3 * p + 2]);
            const double e = (h - r) / r, s = ref.noise_y[p] / r;
            e2 += e * e;
            s2 += s * s;
            sum += e;
            ++out.pixels;
            const std::size_t t = std::size_t(y / kTile) * tiles_x + x / kTile;
            tile_sum[t] += e;
            ++tile_count[t];
        }
    }
    if (out.pixels == 0) return out;
    const double n = double(out.pixels);
    out.raw_rms = std::sqrt(e2 / n);
    out.noise_rms = std::sqrt(s2 / n);
    out.rms = std::sqrt(std::max(0.0, e2 / n - s2 / n));
    out.mean = sum / n;
    for (std::size_t t = 0; t < tile_sum.size(); ++t) {
        if (tile_count[t] * 4 < kTile * kTile) continue;
        const double m = tile_sum[t] / double(tile_count[t]);
        if (std::abs(m) > std::abs(out.worst_tile)) {
            out.worst_tile = m;
            out.worst_tile_x = int(t % tiles_x) * kTile;
            out.worst_tile_y = int(t / tiles_x) * kTile;
        }
    }
    return out;
}

ordered_json compare_faces(const std::string& baked_gltf, const ImageReference& ref) {
    tinygltf::Model model;
    tinygltf::TinyGLTF loader;
    std::string err, warn;
    if (!loader.LoadASCIIFromFile(&model, &err, &warn, baked_gltf))
        throw InputError(fmt::format("{}: cannot read the baked glTF: {}", baked_gltf, err));
    const ordered_json& faces = ref.json.at("faces");
    std::vector<double> area(faces.size(), 0.0);
    std::vector<glm::dvec3> integral(faces.size(), glm::dvec3(0.0));
    for (const tinygltf::Node& node : model.nodes) {
        if (node.mesh < 0) continue;
        for (const tinygltf::Primitive& prim : model.meshes.at(node.mesh).primitives) {
            if (!prim.attributes.count("POSITION") || !prim.attributes.count("COLOR_0")) continue;
            const std::vector<glm::dvec3> pos = read_vec3(model, prim.attributes.at("POSITION"));
            const std::vector<glm::dvec3> col = read_vec3(model, prim.attributes.at("COLOR_0"));
            if (col.size() != pos.size()) throw InputError(fmt::format("{}: COLOR_0 and POSITION differ in count", baked_gltf));
            const std::vector<std::uint32_t> idx = read_indices(model, prim.indices, pos.size());
            for (std::size_t t = 0; t + 2 < idx.size(); t += 3) {
                const glm::dvec3 a = pos[idx[t]], b = pos[idx[t + 1]], c = pos[idx[t + 2]];
                const glm::dvec3 cr = glm::cross(b - a, c - a);
                const double ar = 0.5 * glm::length(cr);
                if (!(ar > 0.0)) continue;
                const glm::dvec3 normal = cr / (2.0 * ar), centre = (a + b + c) / 3.0;
                for (std::size_t f = 0; f < faces.size(); ++f) {
                    if (faces[f].at("node").get<std::string>() != node.name) continue;
                    if (glm::dot(vec3(faces[f].at("normal")), normal) < 0.999) continue;
                    if (std::abs(glm::dot(vec3(faces[f].at("normal")), centre) - faces[f].at("offset").get<double>()) > 1e-4)
                        continue;
                    area[f] += ar;
                    integral[f] += ar * (col[idx[t]] + col[idx[t + 1]] + col[idx[t + 2]]) / 3.0;
                    break;
                }
            }
        }
    }
    ordered_json out = ordered_json::array();
    for (std::size_t f = 0; f < faces.size(); ++f) {
        const glm::dvec3 want = vec3(faces[f].at("radiosity"));
        ordered_json row = {{"node", faces[f].at("node")}, {"normal", faces[f].at("normal")},
                            {"emitter", faces[f].at("emitter")}, {"reference", faces[f].at("radiosity")}};
        if (area[f] > 0.0) {
            const glm::dvec3 got = integral[f] / area[f];
            row["hemirad"] = {got.x, got.y, got.z};
            row["error"] = luminance(got) / luminance(want) - 1.0;
        } else {
            row["hemirad"] = nullptr;
        }
        out.push_back(row);
    }
    return out;
}

ordered_json run_image_accuracy(const ImageAccuracyOptions& o, std::ostream& log) {
    const ImageReference ref = load_image_reference(o.reference_dir);
    {
        std::error_code ec;
        if (!fs::is_regular_file(o.scene, ec))
            throw InputError(fmt::format("{}: not found (run bench --accuracy from the repository root)", o.scene));
    }
    std::vector<Run> runs = {{"draft", "draft", 0, 0.0}, {"default", "default", 0, 0.0}};
    if (!o.quick) {
        runs.push_back({"high", "high", 0, 0.0});
        for (const int n : {64, 128, 512, 1024}) runs.push_back({fmt::format("default, N {}", n), "default", n, 0.0});
        for (const double e : {0.03, 0.015, 0.01})
            runs.push_back({fmt::format("default, elements {:g}", e), "default", 0, e});
    }
    const TempDir temp("hemirad-bench-image");
    log << fmt::format("\nCornell box against the path-traced reference ({}: {}x{}, {} paths a pixel), --device {}\n",
                       o.reference_dir, ref.width, ref.height,
                       ref.json.at("settings").value("samples_per_pixel", 0), o.device);
    log << "| run | bake | elements | solver | pixel RMSE | worst 16x16 tile | worst block face | worst face |\n"
           "|---|---|---|---|---|---|---|---|\n";
    ordered_json out_runs = ordered_json::array();
    for (std::size_t k = 0; k < runs.size(); ++k) {
        const Run& r = runs[k];
        BakeOptions b;
        b.scene = o.scene;
        b.output = (temp.path() / fmt::format("bake-{}", k)).string();
        b.device = o.device;
        b.quality = r.quality;
        b.hemicube = r.hemicube;
        b.element_size = r.element_size;
        b.image_width = ref.width;
        b.output_mode = "radiosity";
        b.quiet = true;
        run_bake(b);
        const ordered_json report = read_report(fs::path(b.output) / "report.json");
        int w = 0, h = 0;
        const std::vector<float> rgb = read_rgb(fs::path(b.output) / "render.exr", w, h);
        const PixelErrors px = compare_pixels(rgb, w, h, ref);
        const ordered_json faces = compare_faces((fs::path(b.output) / "baked.gltf").string(), ref);
        double worst_block = 0.0, worst_face = 0.0;
        std::string worst_block_name, worst_face_name;
        for (const ordered_json& f : faces) {
            if (f.at("emitter").get<bool>() || f.at("hemirad").is_null()) continue;
            const double e = f.at("error").get<double>();
            const std::string node = f.at("node").get<std::string>();
            const glm::dvec3 n = vec3(f.at("normal"));
            const std::string name = fmt::format("{} ({:+.2f},{:+.2f},{:+.2f})", node, n.x, n.y, n.z);
            if (std::abs(e) > std::abs(worst_face)) worst_face = e, worst_face_name = name;
            if (node.find("block") != std::string::npos && std::abs(e) > std::abs(worst_block))
                worst_block = e, worst_block_name = name;
        }
        const double seconds = report.at("timings_s").at("total").get<double>();
        const long elements = report.at("counts").at("elements").get<long>();
        const std::string solver = report.at("settings").value("solver", std::string());
        log << fmt::format("| {} | {:.2f} s | {} | {} | {:.2f}% | {:+.1f}% at ({}, {}) | {:+.2f}% {} | {:+.2f}% {} |\n",
                           r.label, seconds, elements, solver, 100.0 * px.rms, 100.0 * px.worst_tile,
                           px.worst_tile_x, px.worst_tile_y, 100.0 * worst_block, worst_block_name,
                           100.0 * worst_face, worst_face_name);
        log.flush();
        out_runs.push_back({{"label", r.label},
                            {"quality", r.quality},
                            {"options", {{"hemicube", report.at("settings").at("hemicube")},
                                         {"element_size", report.at("settings").at("element_size")},
                                         {"patch_size", report.at("settings").at("patch_size")}}},
                            {"seconds", seconds},
                            {"timings_s", report.at("timings_s")},
                            {"elements", elements},
                            {"solver", solver},
                            {"pixels",
                             {{"rms", px.rms},
                              {"raw_rms", px.raw_rms},
                              {"reference_noise_rms", px.noise_rms},
                              {"mean", px.mean},
                              {"count", px.pixels},
                              {"worst_tile", {{"error", px.worst_tile}, {"x", px.worst_tile_x}, {"y", px.worst_tile_y}}}}},
                            {"worst_block_face", {{"error", worst_block}, {"face", worst_block_name}}},
                            {"worst_face", {{"error", worst_face}, {"face", worst_face_name}}},
                            {"faces", faces}});
        std::error_code ec;
        fs::remove_all(b.output, ec);
    }
    return {{"scene", o.scene},
            {"reference", {{"dir", o.reference_dir},
                           {"image", {ref.width, ref.height}},
                           {"settings", ref.json.at("settings")},
                           {"generator", ref.json.value("generator", std::string())}}},
            {"runs", out_runs}};
}

}  // namespace hemirad::cli
