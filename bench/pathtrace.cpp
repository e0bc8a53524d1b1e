// hemirad_pathtrace: an independent converged reference for `hemirad bench --accuracy`.
//
// A plain Monte Carlo path tracer of diffuse glTF scenes that shares no code with hemirad: it reads
// the file with tinygltf itself, intersects with Embree, and estimates radiosity B = E + ρ·H at
// points (H the irradiance, W/m², hemirad's convention) by next-event estimation on the emitting
// triangles plus cosine-weighted bounces with Russian roulette. It writes, for one camera:
// - reference.exr: per pixel the box-filtered radiosity of the same 3 × 3 sample positions
//   hemirad's renderer uses (channels R, G, B, half floats), the standard error of its Rec. 709
//   luminance (noise.Y), and
//   `face`: the index of the face all 9 samples hit, −1 where they hit more than one (an edge) or
//   nothing;
// - reference.json: the faces (a node's triangles in one plane) with their area-averaged
//   radiosity and its standard error, the per-node averages, and the settings.
// Scope, checked on load: triangles, baseColorFactor and emissiveFactor (× KHR_materials_
// emissive_strength), doubleSided; no textures, vertex colours or punctual lights (refused).
// Same arguments → same bits (a seeded generator per pixel and per face point, any thread count).
#include <embree3/rtcore.h>
#include <tiny_gltf.h>

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <glm/glm.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtc/type_ptr.hpp>
#include <nlohmann/json.hpp>

namespace {

using glm::dvec3;

struct Material {
    dvec3 rho{0.0};
    dvec3 emission{0.0};  // exitance, W/m² (hemirad: emissiveFactor × strength)
    bool double_sided = false;
};

struct Triangle {
    dvec3 p[3];
    dvec3 normal;  // unit, front (counter-clockwise)
    double area = 0.0;
    int material = 0;
    int face = 0;
};

struct Face {
    std::string node;
    dvec3 normal;
    double offset = 0.0;  // normal · p
    double area = 0.0;
    bool emitter = false;
    std::vector<int> triangles;
};

struct Camera {
    glm::dmat4 to_world{1.0};
    double yfov = 0.8;
    double aspect = 1.0;
};

[[noreturn]] void fail(const std::string& what) { throw std::runtime_error(what); }

// A small counter-based generator (splitmix64 to seed, xoshiro256** to draw).
struct Rng {
    std::uint64_t s[4];
    explicit Rng(std::uint64_t seed) {
        for (auto& v : s) {
            seed += 0x9e3779b97f4a7c15ull;
            std::uint64_t z = seed;
            z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
            z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
            v = z ^ (z >> 31);
        }
    }
    static std::uint64_t rotl(std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }
    std::uint64_t next() {
        const std::uint64_t r = rotl(s[1] * 5, 7) * 9, t = s[1] << 17;
        s[2] ^= s[0], s[3] ^= s[1], s[1] ^= s[2], s[0] ^= s[3], s[2] ^= t, s[3] = rotl(s[3], 45);
        return r;
    }
    double uniform() { return double(next() >> 11) * 0x1.0p-53; }
};

class Scene {
public:
    std::vector<Triangle> triangles;
    std::vector<Material> materials;
    std::vector<Face> faces;
    std::vector<std::string> node_names;
    std::vector<int> emitters;           // triangles that emit
    std::vector<double> emitter_cdf;     // by area
    double emitter_area = 0.0;
    double diagonal = 0.0;
    Camera camera;
    bool has_camera = false;

    void load(const std::string& path);
    void build();
    ~Scene() {
        if (scene_) rtcReleaseScene(scene_);
        if (device_) rtcReleaseDevice(device_);
    }

    // The nearest hit along the ray (t in (tmin, tmax)), or -1.
    int intersect(const dvec3& o, const dvec3& d, double tmin, double tmax, double& t) const {
        RTCIntersectContext context;
        rtcInitIntersectContext(&context);
        RTCRayHit rh{};
        rh.ray.org_x = float(o.x), rh.ray.org_y = float(o.y), rh.ray.org_z = float(o.z);
        rh.ray.dir_x = float(d.x), rh.ray.dir_y = float(d.y), rh.ray.dir_z = float(d.z);
        rh.ray.tnear = float(tmin), rh.ray.tfar = float(tmax);
        rh.ray.mask = 0xffffffffu;
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rtcIntersect1(scene_, &context, &rh);
        if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return -1;
        t = rh.ray.tfar;
        return int(rh.hit.primID);
    }
    bool occluded(const dvec3& o, const dvec3& d, double tmin, double tmax) const {
        RTCIntersectContext context;
        rtcInitIntersectContext(&context);
        RTCRay ray{};
        ray.org_x = float(o.x), ray.org_y = float(o.y), ray.org_z = float(o.z);
        ray.dir_x = float(d.x), ray.dir_y = float(d.y), ray.dir_z = float(d.z);
        ray.tnear = float(tmin), ray.tfar = float(tmax);
        ray.mask = 0xffffffffu;
        rtcOccluded1(scene_, &context, &ray);
        return ray.tfar < 0.0f;
    }

private:
    RTCDevice device_ = nullptr;
    RTCScene scene_ = nullptr;
};

glm::dmat4 local_matrix(const tinygltf::Node& n) {
    if (n.matrix.size() == 16) return glm::make_mat4(n.matrix.data());
    glm::dmat4 m(1.0);
    if (n.translation.size() == 3) m = glm::translate(m, dvec3(n.translation[0], n.translation[1], n.translation[2]));
    if (n.rotation.size() == 4) {
        m *= glm::mat4_cast(glm::dquat(n.rotation[3], n.rotation[0], n.rotation[1], n.rotation[2]));
    }
    if (n.scale.size() == 3) m = glm::scale(m, dvec3(n.scale[0], n.scale[1], n.scale[2]));
    return m;
}

double read_scalar(const tinygltf::Model& model, const tinygltf::Accessor& a, std::size_t i, int component) {
    const tinygltf::BufferView& view = model.bufferViews.at(a.bufferView);
    const unsigned char* base = model.buffers.at(view.buffer).data.data() + view.byteOffset + a.byteOffset;
    const int components = tinygltf::GetNumComponentsInType(a.type);
    const int size = tinygltf::GetComponentSizeInBytes(a.componentType);
    const std::size_t stride = view.byteStride ? view.byteStride : std::size_t(components * size);
    const unsigned char* p = base + i * stride + std::size_t(component) * size;
    switch (a.componentType) {
        case TINYGLTF_COMPONENT_TYPE_FLOAT: { float f; std::memcpy(&f, p, 4); return f; }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: { std::uint32_t v; std::memcpy(&v, p, 4); return v; }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: { std::uint16_t v; std::memcpy(&v, p, 2); return v; }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return *p;
        default: fail("unsupported accessor component type");
    }
}

void Scene::load(const std::string& path) {
    tinygltf::Model model;
    tinygltf::TinyGLTF loader;
    std::string err, warn;
    const bool ok = path.size() > 4 && path.substr(path.size() - 4) == ".glb"
                        ? loader.LoadBinaryFromFile(&model, &err, &warn, path)
                        : loader.LoadASCIIFromFile(&model, &err, &warn, path);
    if (!ok) fail(path + ": " + err);
    if (!model.extensionsRequired.empty()) fail(path + ": required extensions are not supported here");
    for (const std::string& e : model.extensionsUsed)
        if (e == "KHR_lights_punctual") fail(path + ": punctual lights are not supported here");
    for (const tinygltf::Material& m : model.materials) {
        Material out;
        const auto& f = m.pbrMetallicRoughness.baseColorFactor;
        out.rho = dvec3(f[0], f[1], f[2]);
        if (m.pbrMetallicRoughness.baseColorTexture.index >= 0 || m.emissiveTexture.index >= 0) {
            fail(path + ": material '" + m.name + "' has a texture; only factors are supported here");
        }
        double strength = 1.0;
        const auto it = m.extensions.find("KHR_materials_emissive_strength");
        if (it != m.extensions.end() && it->second.Has("emissiveStrength"))
            strength = it->second.Get("emissiveStrength").GetNumberAsDouble();
        if (m.emissiveFactor.size() == 3)
            out.emission = dvec3(m.emissiveFactor[0], m.emissiveFactor[1], m.emissiveFactor[2]) * strength;
        out.double_sided = m.doubleSided;
        materials.push_back(out);
    }
    const int default_material = int(materials.size());
    materials.push_back(Material{dvec3(1.0), dvec3(0.0), false});  // glTF's default material

    // Walk the default scene's node tree.
    const int scene_index = model.defaultScene >= 0 ? model.defaultScene : 0;
    std::vector<std::pair<int, glm::dmat4>> stack;
    for (const int root : model.scenes.at(scene_index).nodes) stack.push_back({root, glm::dmat4(1.0)});
    while (!stack.empty()) {
        const auto [index, parent] = stack.back();
        stack.pop_back();
        const tinygltf::Node& node = model.nodes.at(index);
        const glm::dmat4 world = parent * local_matrix(node);
        for (const int child : node.children) stack.push_back({child, world});
        if (node.camera >= 0 && !has_camera) {
            const tinygltf::Camera& c = model.cameras.at(node.camera);
            if (c.type != "perspective") fail(path + ": only perspective cameras");
            camera.to_world = world;
            camera.yfov = c.perspective.yfov;
            camera.aspect = c.perspective.aspectRatio > 0.0 ? c.perspective.aspectRatio : 1.0;
            has_camera = true;
        }
        if (node.mesh < 0) continue;
        const int node_id = int(node_names.size());
        node_names.push_back(node.name);
        const bool mirrored = glm::determinant(glm::dmat3(world)) < 0.0;
        for (const tinygltf::Primitive& prim : model.meshes.at(node.mesh).primitives) {
            if (prim.mode != TINYGLTF_MODE_TRIANGLES && prim.mode != -1) fail(path + ": only triangle primitives");
            if (prim.attributes.count("COLOR_0")) fail(path + ": vertex colours are not supported here");
            const tinygltf::Accessor& pos = model.accessors.at(prim.attributes.at("POSITION"));
            std::vector<std::uint32_t> index_list;
            if (prim.indices >= 0) {
                const tinygltf::Accessor& ia = model.accessors.at(prim.indices);
                for (std::size_t i = 0; i < ia.count; ++i) index_list.push_back(std::uint32_t(read_scalar(model, ia, i, 0)));
            } else {
                for (std::size_t i = 0; i < pos.count; ++i) index_list.push_back(std::uint32_t(i));
            }
            const int material = prim.material >= 0 ? prim.material : default_material;
            for (std::size_t t = 0; t + 2 < index_list.size(); t += 3) {
                Triangle tri;
                for (int k = 0; k < 3; ++k) {
                    const std::uint32_t v = index_list[t + k];
                    const dvec3 local(read_scalar(model, pos, v, 0), read_scalar(model, pos, v, 1),
                                      read_scalar(model, pos, v, 2));
                    tri.p[k] = dvec3(world * glm::dvec4(local, 1.0));
                }
                if (mirrored) std::swap(tri.p[1], tri.p[2]);
                const dvec3 c = glm::cross(tri.p[1] - tri.p[0], tri.p[2] - tri.p[0]);
                tri.area = 0.5 * glm::length(c);
                if (!(tri.area > 0.0)) continue;
                tri.normal = c / (2.0 * tri.area);
                tri.material = material;
                tri.face = node_id;  // a node id until build() groups faces
                triangles.push_back(tri);
            }
        }
    }
    if (triangles.empty()) fail(path + ": no triangles");
}

void Scene::build() {
    dvec3 lo(HUGE_VAL), hi(-HUGE_VAL);
    for (const Triangle& t : triangles)
        for (const dvec3& p : t.p) lo = glm::min(lo, p), hi = glm::max(hi, p);
    diagonal = glm::length(hi - lo);
    // Faces: a node's triangles in one plane.
    for (std::size_t i = 0; i < triangles.size(); ++i) {
        Triangle& t = triangles[i];
        const std::string& node = node_names[t.face];
        const double offset = glm::dot(t.normal, t.p[0]);
        int found = -1;
        for (std::size_t f = 0; f < faces.size() && found < 0; ++f) {
            if (faces[f].node == node && glm::dot(faces[f].normal, t.normal) > 1.0 - 1e-9 &&
                std::abs(faces[f].offset - offset) < 1e-6 * diagonal) {
                found = int(f);
            }
        }
        if (found < 0) {
            found = int(faces.size());
            faces.push_back(Face{node, t.normal, offset, 0.0, false, {}});
        }
        t.face = found;
        faces[found].area += t.area;
        faces[found].triangles.push_back(int(i));
        const Material& m = materials[t.material];
        if (m.emission.x > 0.0 || m.emission.y > 0.0 || m.emission.z > 0.0) {
            faces[found].emitter = true;
            emitters.push_back(int(i));
            emitter_area += t.area;
            emitter_cdf.push_back(emitter_area);
        }
    }
    if (emitters.empty()) fail("the scene emits nothing");
    device_ = rtcNewDevice(nullptr);
    if (!device_) fail("embree: rtcNewDevice failed");
    scene_ = rtcNewScene(device_);
    rtcSetSceneBuildQuality(scene_, RTC_BUILD_QUALITY_HIGH);
    RTCGeometry geom = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_TRIANGLE);
    auto* v = static_cast<float*>(
        rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), 3 * triangles.size()));
    auto* idx = static_cast<std::uint32_t*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                                   3 * sizeof(std::uint32_t), triangles.size()));
    for (std::size_t i = 0; i < triangles.size(); ++i) {
        for (int k = 0; k < 3; ++k) {
            for (int c = 0; c < 3; ++c) v[9 * i + 3 * k + c] = float(triangles[i].p[k][c]);
            idx[3 * i + k] = std::uint32_t(3 * i + k);
        }
    }
    rtcCommitGeometry(geom);
    rtcAttachGeometry(scene_, geom);
    rtcReleaseGeometry(geom);
    rtcCommitScene(scene_);
}

// A point on a surface, seen from one side: its normal faces the side light arrives from.
struct Hit {
    int triangle = -1;
    dvec3 p{0.0}, n{0.0};
    bool back = false;  // the back of a one-sided surface: absorbs, emits nothing
};

class Tracer {
public:
    explicit Tracer(const Scene& scene) : s_(scene), eps_(1e-5 * scene.diagonal) {}

    Hit trace(const dvec3& o, const dvec3& d) const {
        double t = 0.0;
        const int k = s_.intersect(o, d, eps_, 1e30, t);
        Hit h;
        if (k < 0) return h;
        h.triangle = k;
        h.p = o + t * d;
        const Triangle& tri = s_.triangles[k];
        const bool front = glm::dot(tri.normal, d) < 0.0;
        h.n = front ? tri.normal : -tri.normal;
        h.back = !front && !s_.materials[tri.material].double_sided;
        return h;
    }

    // One sample of the irradiance H at a point with normal n (light arriving on n's side).
    dvec3 irradiance(dvec3 p, dvec3 n, Rng& rng) const {
        dvec3 total(0.0), weight(1.0);
        for (int depth = 0;; ++depth) {
            total += weight * direct(p, n, rng);
            // Russian roulette on the path's weight after a few bounces.
            const dvec3 d = cosine_direction(n, rng);
            const Hit h = trace(p, d);
            if (h.triangle < 0 || h.back) break;
            const Material& m = s_.materials[s_.triangles[h.triangle].material];
            weight *= m.rho;  // H(x) gets ρ_y H(y) per cosine-weighted sample (π L_in, L = ρ H / π)
            if (depth >= 3) {
                const double q = std::min(0.95, std::max({weight.x, weight.y, weight.z}));
                if (q <= 0.0 || rng.uniform() >= q) break;
                weight /= q;
            }
            p = h.p;
            n = h.n;
        }
        return total;
    }

    // Radiosity leaving a hit point toward the viewer: E (front of an emitter) + ρ H.
    dvec3 radiosity(const Hit& h, Rng& rng) const {
        if (h.triangle < 0 || h.back) return dvec3(0.0);
        const Triangle& tri = s_.triangles[h.triangle];
        const Material& m = s_.materials[tri.material];
        const bool front = glm::dot(h.n, tri.normal) > 0.0;
        const dvec3 e = front ? m.emission : (m.double_sided ? m.emission : dvec3(0.0));
        return e + m.rho * irradiance(h.p, h.n, rng);
    }

private:
    // Next-event estimation: one point on the emitters, chosen by area.
    dvec3 direct(const dvec3& p, const dvec3& n, Rng& rng) const {
        const double u = rng.uniform() * s_.emitter_area;
        const std::size_t i = std::min<std::size_t>(
            s_.emitter_cdf.size() - 1,
            std::size_t(std::upper_bound(s_.emitter_cdf.begin(), s_.emitter_cdf.end(), u) - s_.emitter_cdf.begin()));
        const Triangle& e = s_.triangles[s_.emitters[i]];
        double a = rng.uniform(), b = rng.uniform();
        if (a + b > 1.0) a = 1.0 - a, b = 1.0 - b;
        const dvec3 q = e.p[0] + a * (e.p[1] - e.p[0]) + b * (e.p[2] - e.p[0]);
        const dvec3 to = q - p;
        const double r2 = glm::dot(to, to);
        if (!(r2 > 0.0)) return dvec3(0.0);
        const double r = std::sqrt(r2);
        const dvec3 d = to / r;
        const double cos_x = glm::dot(n, d);
        if (cos_x <= 0.0) return dvec3(0.0);
        const Material& m = s_.materials[e.material];
        double cos_e = -glm::dot(e.normal, d);
        if (cos_e <= 0.0) {
            if (!m.double_sided) return dvec3(0.0);
            cos_e = -cos_e;
        }
        if (s_.occluded(p, d, eps_, r * (1.0 - 1e-6) - eps_)) return dvec3(0.0);
        // L_e = E/π; H += L_e cos_x cos_e / r² · A_total
        return m.emission / M_PI * (cos_x * cos_e / r2) * s_.emitter_area;
    }

    static dvec3 cosine_direction(const dvec3& n, Rng& rng) {
        const double u1 = rng.uniform(), u2 = rng.uniform();
        const double r = std::sqrt(u1), phi = 2.0 * M_PI * u2;
        const dvec3 t = std::abs(n.x) > 0.5 ? glm::normalize(glm::cross(n, dvec3(0, 1, 0)))
                                            : glm::normalize(glm::cross(n, dvec3(1, 0, 0)));
        const dvec3 b = glm::cross(n, t);
        return glm::normalize(r * std::cos(phi) * t + r * std::sin(phi) * b + std::sqrt(std::max(0.0, 1.0 - u1)) * n);
    }

    const Scene& s_;
    double eps_;
};

struct Options {
    std::string scene, out = ".";
    int width = 640;
    int spp = 64;          // paths per sample position (9 positions a pixel)
    int face_points = 4096;
    int face_spp = 64;
    std::uint64_t seed = 1;
    int threads = 0;
};

template <class Fn>
void parallel_for(int count, int threads, Fn fn) {
    std::atomic<int> next{0};
    std::vector<std::thread> pool;
    for (int t = 0; t < threads; ++t)
        pool.emplace_back([&] {
            for (int i; (i = next.fetch_add(1)) < count;) fn(i);
        });
    for (auto& th : pool) th.join();
}

std::uint64_t mix(std::uint64_t a, std::uint64_t b) { return a * 0x9e3779b97f4a7c15ull ^ (b + 0x632be59bd9b4e019ull + (a << 6)); }

double luminance(const dvec3& c) { return 0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z; }

int run(const Options& o) {
    const auto start = std::chrono::steady_clock::now();
    Scene scene;
    scene.load(o.scene);
    scene.build();
    if (!scene.has_camera && o.width > 0) fail(o.scene + ": no camera (--width 0 computes the faces alone)");
    const Tracer tracer(scene);
    const int threads = o.threads > 0 ? o.threads : int(std::max(1u, std::thread::hardware_concurrency()));
    const int W = o.width, H = o.width > 0 ? int(std::lround(o.width / scene.camera.aspect)) : 0;
    constexpr int kSub = 3;  // hemirad's renderer: 3 × 3 samples a pixel at (i + 0.5) / 3, box-filtered
    const double f = 1.0 / std::tan(0.5 * scene.camera.yfov);
    const double sx = f * double(H) / double(W), sy = f;
    const dvec3 eye(scene.camera.to_world * glm::dvec4(0, 0, 0, 1));
    const glm::dmat3 rot(scene.camera.to_world);

    std::vector<float> rgb(std::size_t(W) * H * 3), noise(std::size_t(W) * H), face(std::size_t(W) * H);
    parallel_for(H, threads, [&](int y) {
        for (int x = 0; x < W; ++x) {
            Rng rng(mix(mix(o.seed, 0x5eed), std::uint64_t(y) * W + x));
            dvec3 sum(0.0);
            double lum2 = 0.0;
            int first_face = -2;
            bool one_face = true;
            for (int j = 0; j < kSub; ++j) {
                for (int i = 0; i < kSub; ++i) {
                    const double ndc_x = 2.0 * (x * kSub + i + 0.5) / (double(W) * kSub) - 1.0;
                    const double ndc_y = 1.0 - 2.0 * (y * kSub + j + 0.5) / (double(H) * kSub);
                    const dvec3 d = glm::normalize(rot * dvec3(ndc_x / sx, ndc_y / sy, -1.0));
                    const Hit h = tracer.trace(eye, d);
                    const int fc = h.triangle >= 0 && !h.back ? scene.triangles[h.triangle].face : -1;
                    if (first_face == -2) first_face = fc;
                    one_face = one_face && fc == first_face && fc >= 0;
                    for (int s = 0; s < o.spp; ++s) {
                        const dvec3 b = tracer.radiosity(h, rng);
                        sum += b;
                        lum2 += luminance(b) * luminance(b);
                    }
                }
            }
            const double n = double(kSub * kSub) * o.spp;
            const dvec3 mean = sum / n;
            const std::size_t p = std::size_t(y) * W + x;
            for (int c = 0; c < 3; ++c) rgb[3 * p + c] = float(mean[c]);
            const double lum_var = std::max(0.0, (lum2 / n - luminance(mean) * luminance(mean)) * (n / (n - 1.0)));
            noise[p] = float(std::sqrt(lum_var / n));
            face[p] = one_face ? float(first_face) : -1.0f;
        }
    });

    // Faces: area averages from stratified points.
    struct FaceResult {
        dvec3 mean{0.0}, stderr_{0.0};
    };
    std::vector<FaceResult> face_results(scene.faces.size());
    parallel_for(int(scene.faces.size()), threads, [&](int fi) {
        const Face& fc = scene.faces[fi];
        Rng rng(mix(mix(o.seed, 0xface), std::uint64_t(fi)));
        std::vector<double> cdf;
        double acc = 0.0;
        for (const int t : fc.triangles) cdf.push_back(acc += scene.triangles[t].area);
        dvec3 sum(0.0), sum2(0.0);
        for (int k = 0; k < o.face_points; ++k) {
            const double u = (k + rng.uniform()) / o.face_points * acc;  // stratified over area
            const std::size_t ti = std::min<std::size_t>(cdf.size() - 1, std::size_t(std::upper_bound(cdf.begin(), cdf.end(), u) - cdf.begin()));
            const Triangle& t = scene.triangles[fc.triangles[ti]];
            double a = rng.uniform(), b = rng.uniform();
            if (a + b > 1.0) a = 1.0 - a, b = 1.0 - b;
            Hit h;
            h.triangle = fc.triangles[ti];
            h.p = t.p[0] + a * (t.p[1] - t.p[0]) + b * (t.p[2] - t.p[0]);
            h.n = t.normal;
            dvec3 point(0.0);
            for (int s = 0; s < o.face_spp; ++s) point += tracer.radiosity(h, rng);
            point /= double(o.face_spp);
            sum += point;
            sum2 += point * point;
        }
        const double n = o.face_points;
        face_results[fi].mean = sum / n;
        face_results[fi].stderr_ = glm::sqrt(glm::max(dvec3(0.0), (sum2 / n - (sum / n) * (sum / n)) / (n - 1.0)));
    });
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

    std::filesystem::create_directories(o.out);
    const std::filesystem::path exr = std::filesystem::path(o.out) / "reference.exr";
    if (W > 0) {
        // Half floats (0.05% steps, far below the noise) keep the committed file small.
        OIIO::ImageSpec spec(W, H, 5, OIIO::TypeDesc::HALF);
        spec.channelnames = {"R", "G", "B", "noise.Y", "face"};
        spec.attribute("compression", "zip");
        std::vector<float> pixels(std::size_t(W) * H * 5);
        for (std::size_t p = 0; p < std::size_t(W) * H; ++p) {
            for (int c = 0; c < 3; ++c) pixels[5 * p + c] = rgb[3 * p + c];
            pixels[5 * p + 3] = noise[p];
            pixels[5 * p + 4] = face[p];
        }
        auto out = OIIO::ImageOutput::create(exr.string());
        if (!out || !out->open(exr.string(), spec) || !out->write_image(OIIO::TypeDesc::FLOAT, pixels.data())) {
            fail("cannot write " + exr.string());
        }
        out->close();
    }
    nlohmann::ordered_json j;
    j["generator"] = "hemirad_pathtrace (bench/pathtrace.cpp)";
    j["scene"] = std::filesystem::path(o.scene).filename().string();
    j["image"] = {W, H};
    j["settings"] = {{"paths_per_sample", o.spp}, {"samples_per_pixel", 9 * o.spp}, {"face_points", o.face_points},
                     {"face_paths_per_point", o.face_spp}, {"seed", o.seed}};
    j["seconds"] = seconds;
    j["threads"] = threads;
    std::map<std::string, std::pair<double, dvec3>> nodes;
    nlohmann::ordered_json faces = nlohmann::ordered_json::array();
    for (std::size_t fi = 0; fi < scene.faces.size(); ++fi) {
        const Face& fc = scene.faces[fi];
        const FaceResult& r = face_results[fi];
        faces.push_back({{"index", fi},
                         {"node", fc.node},
                         {"normal", {fc.normal.x, fc.normal.y, fc.normal.z}},
                         {"offset", fc.offset},
                         {"area", fc.area},
                         {"emitter", fc.emitter},
                         {"radiosity", {r.mean.x, r.mean.y, r.mean.z}},
                         {"stderr", {r.stderr_.x, r.stderr_.y, r.stderr_.z}}});
        auto& node = nodes[fc.node];
        node.first += fc.area;
        node.second += fc.area * r.mean;
    }
    j["faces"] = faces;
    nlohmann::ordered_json meshes = nlohmann::ordered_json::array();
    for (const std::string& name : scene.node_names) {
        const auto& node = nodes[name];
        const dvec3 b = node.second / node.first;
        meshes.push_back({{"name", name}, {"area", node.first}, {"radiosity", {b.x, b.y, b.z}}});
    }
    j["meshes"] = meshes;
    std::ofstream(std::filesystem::path(o.out) / "reference.json") << j.dump(1) << "\n";

    // The noise, for the log: mean relative standard error over pixels that hit one face.
    double rel = 0.0;
    std::size_t count = 0;
    for (std::size_t p = 0; p < std::size_t(W) * H; ++p) {
        const double l = luminance(dvec3(rgb[3 * p], rgb[3 * p + 1], rgb[3 * p + 2]));
        if (face[p] >= 0.0f && l > 0.0) {
            rel += noise[p] / l;
            ++count;
        }
    }
    std::printf("hemirad_pathtrace: %dx%d, %d paths a pixel, %zu faces, %.1f s on %d threads; mean relative noise %.3g%%\n",
                W, H, 9 * o.spp, scene.faces.size(), seconds, threads, count ? 100.0 * rel / double(count) : 0.0);
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    Options o;
    try {
        for (int i = 1; i < argc; ++i) {
            const std::string a = argv[i];
            auto value = [&]() -> std::string {
                if (i + 1 >= argc) fail(a + " needs a value");
                return argv[++i];
            };
            if (a == "--out") o.out = value();
            else if (a == "--width") o.width = std::stoi(value());
            else if (a == "--spp") o.spp = std::stoi(value());
            else if (a == "--face-points") o.face_points = std::stoi(value());
            else if (a == "--face-spp") o.face_spp = std::stoi(value());
            else if (a == "--seed") o.seed = std::stoull(value());
            else if (a == "--threads") o.threads = std::stoi(value());
            else if (!a.empty() && a[0] != '-' && o.scene.empty()) o.scene = a;
            else fail("unknown argument " + a);
        }
        if (o.scene.empty()) {
            std::fprintf(stderr, "usage: hemirad_pathtrace SCENE.gltf [--out DIR] [--width W (0: no image)] [--spp S] "
                                 "[--face-points P] [--face-spp S] [--seed X] [--threads T]\n");
            return 2;
        }
        if (o.width < 0 || o.spp < 1 || o.face_points < 2 || o.face_spp < 1) fail("counts must be positive");
        return run(o);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "hemirad_pathtrace: %s\n", e.what());
        return 2;
    }
}
