// Directional lights (suns) as shooters like any other (formfactor::Shooter::Kind::directional):
// every engine answers a directional request with the host's parallel shot (formfactor/parallel.h)
// bit for bit, drawn on its own raster; the decorators pass it on like any shot, the sharded
// engine shares it, --verify checks its grid exactly, and the solve's direct light sends the
// mesh's suns through the engine as one batch, under the shot counters it always used.
#include <catch2/catch.hpp>

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "backends.h"
#include "cl/runtime.h"
#include "core/error.h"
#include "dist/dist.h"
#include "formfactor/near_field.h"
#include "formfactor/hemicube.h"
#include "formfactor/opencl_engine.h"
#include "formfactor/parallel.h"
#include "formfactor/reference.h"
#include "formfactor/row_cache.h"
#include "formfactor/sharded.h"
#include "formfactor/timed.h"
#include "formfactor/unoccluded.h"
#include "formfactor/verify.h"
#include "mesh/mesh.h"
#include "mesh/refine.h"
#include "scene/builder.h"
#include "scene/scene.h"
#include "solve/lights.h"
#ifdef HEMIRAD_HAVE_EMBREE
#include "formfactor/embree_engine.h"
#endif

namespace {

using namespace hemirad;
using formfactor::ShotRequest;
using formfactor::ShotResult;
using glm::dvec3;

scene::PunctualLight sun(const dvec3& direction, double lux) {
    scene::PunctualLight l;
    l.type = scene::PunctualLight::Type::directional;
    l.direction = glm::normalize(direction);
    l.intensity = dvec3(lux);
    return l;
}

// A floor under a one-sided roof (its back blocks) beside a double-sided card, lit by a point
// light, two suns and a directional light of intensity 0 (which does not shine).
scene::Scene sunlit() {
    scene::Scene s;
    const std::uint32_t grey = scene::add_material(s, dvec3(0.5), dvec3(0.0));
    const std::uint32_t twin = scene::add_material(s, dvec3(0.5), dvec3(0.0), /*double_sided=*/true);
    scene::add_quad(s, {-1, 0, -1}, {-1, 0, 1}, {1, 0, 1}, {1, 0, -1}, grey, "floor");
    scene::add_quad(s, {-0.5, 1, -0.5}, {0.5, 1, -0.5}, {0.5, 1, 0.5}, {-0.5, 1, 0.5}, grey, "roof");
    scene::add_quad(s, {2, 1, 0}, {2, 1, 0.5}, {2.5, 1, 0.5}, {2.5, 1, 0}, twin, "card");
    scene::PunctualLight point;
    point.position = dvec3(0.0, 2.0, 0.0);
    point.intensity = dvec3(2.0);
    s.lights = {point, sun({0.3, -1.0, 0.2}, 3.0), sun({0.0, -1.0, 0.0}, 0.0), sun({-0.5, -1.0, 0.1}, 1.5)};
    scene::finish(s);
    return s;
}

// What every engine must give for a directional request: the host's parallel shot, and its grid.
struct HostShot {
    ShotResult row;
    std::vector<std::int32_t> owner;
};
HostShot host_shot(const mesh::Mesh& m, const ShotRequest& r) {
    HostShot h;
    formfactor::shoot_parallel(m, m.directions.at(r.shooter.patch).direction, r.shot, h.row, {}, nullptr, &h.owner);
    return h;
}

// Patches' shots with the suns' among them, as a solve and its lights might mix them.
std::vector<ShotRequest> mixed_batch(const mesh::Mesh& m) {
    std::vector<ShotRequest> shots;
    for (std::uint32_t p = 0; p < m.patches.size(); p += 3) shots.push_back(ShotRequest::of_patch(p, 11 * p + 1));
    shots.insert(shots.begin() + 1, ShotRequest::of_directional(0, 5));
    shots.push_back(ShotRequest::of_directional(1, 6));
    shots.push_back(ShotRequest::of_light(0, std::uint64_t{1} << 42));
    shots.push_back(ShotRequest::of_directional(0, 9));
    return shots;
}

std::string failure(const std::exception& e) {
    return dynamic_cast<const ocl::DeviceError*>(&e) ? e.what() : std::string();
}

// Passes shots to the engine it wraps and keeps every batch it was given.
class Recording final : public formfactor::Engine {
public:
    explicit Recording(formfactor::Engine& inner) : inner_(inner) {}
    std::string name() const override { return "recording"; }
    using formfactor::Engine::shoot;
    void shoot(const ShotRequest& r, ShotResult& out) override { inner_.shoot(r, out); batches.push_back({r}); }
    void shoot_batch(const std::vector<ShotRequest>& shots, std::vector<ShotResult>& out) override {
        inner_.shoot_batch(shots, out);
        batches.push_back(shots);
    }
    std::vector<std::vector<ShotRequest>> batches;

private:
    formfactor::Engine& inner_;
};

// The reference, with its directional rows or grids altered: what --verify must catch.
class Wrong final : public formfactor::Engine {
public:
    enum class What { nothing, row_bits, row, owner };
    Wrong(const mesh::Mesh& m, What what) : inner_(m, {32, 1}), what_(what) {}
    std::string name() const override { return "wrong"; }
    using formfactor::Engine::shoot;
    void shoot(const ShotRequest& r, ShotResult& out) override {
        inner_.shoot(r, out);
        owner_ = *inner_.last_ids();
        if (r.shooter.kind != formfactor::Shooter::Kind::directional) return;
        if (what_ == What::row_bits) out.F.back() = std::nextafter(out.F.back(), 2.0);  // within any tolerance
        if (what_ == What::row) out.F.back() *= 1.5;
        if (what_ == What::owner) owner_[owner_.size() / 2] += 1;  // a cell given to another record
    }
    const std::vector<std::int32_t>* last_ids(std::size_t i) const override { return i == 0 ? &owner_ : nullptr; }

private:
    formfactor::ReferenceEngine inner_;
    What what_;
    std::vector<std::int32_t> owner_;
};

}  // namespace

TEST_CASE("the mesh carries the scene's shining directional lights, through refinement, the gather's copy and MPI's bytes",
          "[sun][directional]") {
    const scene::Scene s = sunlit();
    const mesh::Mesh m = mesh::build(s, {0.25, 0.125});
    REQUIRE(m.directions.size() == 2);  // the sun of intensity 0 does not shine
    CHECK(m.directions[0].light == 1);
    CHECK(m.directions[1].light == 3);
    CHECK(m.directions[1].direction == s.lights[3].direction);
    CHECK(m.lights.size() == 2);  // the point light's two hemicubes

    std::vector<bool> split(m.elements.size(), false);
    split[0] = true;
    const mesh::Mesh refined = mesh::split_elements(m, split, nullptr).mesh;
    CHECK(refined.elements.size() > m.elements.size());
    REQUIRE(refined.directions.size() == 2);
    CHECK(refined.directions[1].direction == m.directions[1].direction);

    const mesh::Mesh back = dist::unpack_mesh(dist::pack_mesh(m));
    REQUIRE(back.directions.size() == 2);
    CHECK(back.directions[0].direction == m.directions[0].direction);
    CHECK(back.directions[1].light == 3);
    // A directional request is a kind byte like any other: 13 bytes a shot.
    const std::vector<ShotRequest> shots = mixed_batch(m);
    std::uint64_t id = 0;
    const std::string packed = dist::pack_shots(3, shots);
    CHECK(packed.size() == 16 + 13 * shots.size());
    const std::vector<ShotRequest> shots_back = dist::unpack_shots(packed, id);
    REQUIRE(shots_back.size() == shots.size());
    for (std::size_t i = 0; i < shots.size(); ++i) {
        CHECK(shots_back[i].shooter == shots[i].shooter);
        CHECK(shots_back[i].shot == shots[i].shot);
    }
    // The unpacked mesh shoots the same suns.
    formfactor::ReferenceEngine a(m, {32, 1}), b(back, {32, 1});
    std::vector<ShotResult> ra, rb;
    a.shoot_batch(shots, ra);
    b.shoot_batch(shots, rb);
    CHECK(ra == rb);
}

TEST_CASE("a directional shot is the host's parallel shot, bit for bit, on the reference, the sharded, the unoccluded "
          "and the ray-casting engines, and through every decorator",
          "[sun][directional][sharded]") {
    const scene::Scene s = sunlit();
    const mesh::Mesh m = mesh::build(s, {0.25, 0.125});
    const formfactor::Settings settings{32, 1};
    const std::vector<ShotRequest> shots = mixed_batch(m);

    // The reference, one shot at a time: the host's row, and its grid as the shot's ids.
    formfactor::ReferenceEngine ref(m, settings);
    std::vector<ShotResult> want(shots.size());
    std::size_t directional = 0;
    for (std::size_t i = 0; i < shots.size(); ++i) {
        ref.shoot(shots[i], want[i]);
        if (shots[i].shooter.kind != formfactor::Shooter::Kind::directional) continue;
        ++directional;
        const HostShot host = host_shot(m, shots[i]);
        CHECK(want[i] == host.row);
        CHECK(want[i].size() > 0);
        CHECK(want[i].blocked > 0.5);  // the roof's back, in m²: no form factor
        REQUIRE(ref.last_ids() != nullptr);
        CHECK(*ref.last_ids() == host.owner);
    }
    REQUIRE(directional == 3);
    // The grid turns with the shot counter: the same sun under another counter is another grid.
    CHECK(host_shot(m, ShotRequest::of_directional(0, 5)).owner != host_shot(m, ShotRequest::of_directional(0, 9)).owner);

    SECTION("two members share the batch, the suns among its shots") {
        auto stats = std::make_shared<formfactor::ShardStats>();
        std::vector<formfactor::ShardedEngine::Member> list;
        list.push_back({std::make_unique<formfactor::ReferenceEngine>(m, settings), "ref 0", false});
        list.push_back({std::make_unique<formfactor::ReferenceEngine>(m, settings), "ref 1", false});
        formfactor::ShardedEngine sharded(std::move(list), failure, stats);
        std::vector<ShotResult> got;
        sharded.shoot_batch(shots, got);
        CHECK(got == want);
        // A batch of suns alone is shared too: every shot is counted to a member.
        const std::vector<ShotRequest> suns = {ShotRequest::of_directional(0, 1), ShotRequest::of_directional(1, 2),
                                               ShotRequest::of_directional(0, 3), ShotRequest::of_directional(1, 4)};
        sharded.shoot_batch(suns, got);
        for (std::size_t i = 0; i < suns.size(); ++i) CHECK(got[i] == host_shot(m, suns[i]).row);
        long counted = 0;
        for (const auto& member : stats->members) counted += member.shots;
        CHECK(counted == static_cast<long>(shots.size() + suns.size()));
    }
    SECTION("the decorators: near field leaves the suns' rows alone, the row cache passes them on, the timer times them") {
        formfactor::ReferenceEngine inner(m, settings);
        auto near = std::make_unique<formfactor::NearFieldEngine>(m, std::make_unique<Recording>(inner));
        formfactor::RowCacheEngine cache(std::move(near), 1e9);
        formfactor::TimedEngine timed(cache);
        std::vector<ShotResult> got;
        timed.shoot_batch(shots, got);
        for (std::size_t i = 0; i < shots.size(); ++i)
            if (shots[i].shooter.kind == formfactor::Shooter::Kind::directional) CHECK(got[i] == want[i]);
        CHECK(timed.seconds() > 0.0);
        CHECK(cache.stats().requests == static_cast<long>(shots.size()));
        CHECK(cache.stats().shot == static_cast<long>(shots.size()));
        // Asked again: a sun shoots once a level, its row is not kept.
        timed.shoot(ShotRequest::of_directional(1, 6), got.front());
        CHECK(got.front() == host_shot(m, ShotRequest::of_directional(1, 6)).row);
        CHECK(cache.stats().hits == 0);
    }
    SECTION("the unoccluded engine takes the host's parallel shot, shadows and all") {
        formfactor::UnoccludedEngine unoccluded(m);
        std::vector<ShotResult> got;
        unoccluded.shoot_batch(shots, got);
        for (std::size_t i = 0; i < shots.size(); ++i)
            if (shots[i].shooter.kind == formfactor::Shooter::Kind::directional) CHECK(got[i] == want[i]);
    }
#ifdef HEMIRAD_HAVE_EMBREE
    SECTION("the ray-casting engine takes the host's parallel shot") {
        formfactor::EmbreeEngine rays(m, settings, 2);
        std::vector<ShotResult> got;
        rays.shoot_batch(shots, got);
        for (std::size_t i = 0; i < shots.size(); ++i)
            if (shots[i].shooter.kind == formfactor::Shooter::Kind::directional) CHECK(got[i] == want[i]);
        ShotResult one;
        rays.shoot(shots[1], one);
        CHECK(one == want[1]);
    }
#endif
    SECTION("a hemicube of a directional light, or a light the mesh does not have, is refused") {
        ShotResult row;
        CHECK_THROWS_AS(ref.shoot(ShotRequest::of_directional(2, 1), row), InternalError);
        CHECK_THROWS_AS(formfactor::make_frame(m, formfactor::Shooter::of_directional(0), 1, 1), InternalError);
    }
}

TEST_CASE("verification checks every directional shot exactly: each cell's owner and the row's bits", "[sun][directional][verify]") {
    const scene::Scene s = sunlit();
    const mesh::Mesh m = mesh::build(s, {0.25, 0.125});
    const formfactor::Settings settings{32, 1};
    // Counters 5 and 9 are not multiples of 1000: a patch's shot there would go unchecked.
    const std::vector<ShotRequest> suns = {ShotRequest::of_directional(0, 5), ShotRequest::of_directional(1, 9)};
    using What = Wrong::What;
    for (const What what : {What::nothing, What::row_bits, What::row, What::owner}) {
        DYNAMIC_SECTION("altered: " << static_cast<int>(what)) {
            formfactor::VerifyingEngine verifying(std::make_unique<Wrong>(m, what),
                                                  std::make_unique<formfactor::ReferenceEngine>(m, settings), 1000);
            ShotResult row;
            if (what == What::nothing) {
                for (const ShotRequest& r : suns) verifying.shoot(r, row);
                CHECK(verifying.summary().shots_checked == 2);
                CHECK(verifying.summary().cells_compared > 10000);
                CHECK(verifying.summary().cells_mismatched == 0);
            } else {
                CHECK_THROWS_AS(verifying.shoot(suns[1], row), formfactor::VerifyError);
            }
        }
    }
}

TEST_CASE("the direct light shoots the mesh's suns as one batch through the engine, under the counters it always used",
          "[sun][directional][lights]") {
    const scene::Scene s = sunlit();
    const mesh::Mesh m = mesh::build(s, {0.25, 0.125});
    formfactor::ReferenceEngine ref(m, {32, 1});
    Recording recording(ref);
    const int level = 2;
    glm::dvec3 landed(0.0);
    const std::vector<glm::dvec3> H = solve::direct_light(m, s.lights, recording, level, &landed);
    REQUIRE(recording.batches.size() == 2);  // the suns, then the point light's hemicubes
    const std::vector<ShotRequest>& suns = recording.batches.front();
    REQUIRE(suns.size() == 2);
    for (std::size_t d = 0; d < suns.size(); ++d) {
        CHECK(suns[d].shooter == formfactor::Shooter::of_directional(static_cast<std::uint32_t>(d)));
        CHECK(suns[d].shot == level * s.lights.size() + m.directions[d].light);  // 9 and 11
    }
    CHECK(recording.batches.back().front().shooter.kind == formfactor::Shooter::Kind::light);

    // The irradiance as the suns' parallel shots and the point light's hemicubes give it, summed in
    // the order the solve always summed them: suns first, in light order.
    std::vector<glm::dvec3> want(m.elements.size(), glm::dvec3(0.0));
    for (std::size_t d = 0; d < m.directions.size(); ++d) {
        ShotResult lit;
        formfactor::shoot_parallel(m, m.directions[d].direction, level * s.lights.size() + m.directions[d].light, lit);
        for (std::size_t i = 0; i < lit.size(); ++i) want[lit.element[i]] += s.lights[m.directions[d].light].intensity * lit.F[i];
    }
    std::vector<ShotResult> rows;
    ref.shoot_batch(recording.batches.back(), rows);
    for (std::size_t r = 0; r < rows.size(); ++r) {
        const mesh::LightShooter& shooter = m.lights[r];
        const scene::PunctualLight& light = s.lights[shooter.light];
        for (std::size_t i = 0; i < rows[r].size(); ++i) {
            const mesh::Element& e = m.elements[rows[r].element[i]];
            want[rows[r].element[i]] +=
                light.intensity * (light.attenuation(e.centroid - shooter.position) * 4.0 * M_PI * rows[r].F[i]) / e.area;
        }
    }
    CHECK(H == want);
    CHECK(landed.x > 0.0);

    // A mesh whose suns are not the lights': refused, not lit wrongly.
    std::vector<scene::PunctualLight> other = s.lights;
    other[2].intensity = dvec3(1.0);  // a third sun the mesh lacks
    CHECK_THROWS_AS(solve::direct_light(m, other, ref, level), InternalError);
    other = s.lights;
    other[1].direction = glm::normalize(dvec3(0.0, -1.0, 0.3));
    CHECK_THROWS_AS(solve::direct_light(m, other, ref, level), InternalError);
}

TEST_CASE("a directional shot on every OpenCL device's engine is the host's row and grid, alone or among hemicubes",
          "[sun][directional][opencl]") {
    HEMIRAD_SKIP_ABSENT(test::first_opencl());
    const auto devices = ocl::list_devices();
    const scene::Scene s = sunlit();
    const mesh::Mesh m = mesh::build(s, {0.25, 0.125});
    const formfactor::Settings settings{32, 1};
    const std::vector<ShotRequest> shots = mixed_batch(m);
    formfactor::ReferenceEngine ref(m, settings);
    std::vector<ShotResult> want;
    ref.shoot_batch(shots, want);
    std::size_t last_sun = 0;
    for (std::size_t i = 0; i < shots.size(); ++i)
        if (shots[i].shooter.kind == formfactor::Shooter::Kind::directional) last_sun = i;
    bool ran = false;
    for (const ocl::DeviceInfo& info : devices) {
        if (!info.fp64) continue;
        ran = true;
        INFO(info.name);
        ocl::Context context(info);
        formfactor::OpenCLEngine engine(m, context, settings);
        std::vector<ShotResult> got;
        engine.shoot_batch(shots, got);
        REQUIRE(got.size() == shots.size());
        for (std::size_t i = 0; i < shots.size(); ++i) {
            CAPTURE(i);
            if (shots[i].shooter.kind == formfactor::Shooter::Kind::directional) {
                const HostShot host = host_shot(m, shots[i]);
                CHECK(got[i] == host.row);
                // The grid of the batch's last directional shot is kept (up to 64 MiB), the others' not.
                if (i == last_sun) {
                    REQUIRE(engine.last_ids(i) != nullptr);
                    CHECK(*engine.last_ids(i) == host.owner);
                } else {
                    CHECK(engine.last_ids(i) == nullptr);
                }
            } else {
                CHECK(formfactor::compare_shot(got[i], want[i]).empty());
                REQUIRE(engine.last_ids(i) != nullptr);
                CHECK(engine.last_ids(i)->size() == ref.delta().cells());
            }
        }
        // One at a time, and a batch of suns alone.
        ShotResult one;
        engine.shoot(ShotRequest::of_directional(1, 6), one);
        CHECK(one == host_shot(m, ShotRequest::of_directional(1, 6)).row);
        const std::vector<ShotRequest> suns = {ShotRequest::of_directional(1, 2), ShotRequest::of_directional(0, 3)};
        engine.shoot_batch(suns, got);
        for (std::size_t i = 0; i < suns.size(); ++i) CHECK(got[i] == host_shot(m, suns[i]).row);

        // Checked as --verify checks it: every cell's owner, and the row's bits.
        formfactor::VerifyingEngine verifying(std::make_unique<formfactor::OpenCLEngine>(m, context, settings),
                                              std::make_unique<formfactor::ReferenceEngine>(m, settings), 1000);
        verifying.shoot_batch(shots, got);
        CHECK(verifying.summary().shots_checked >= 3);
        CHECK(verifying.summary().cells_compared > 10000);
    }
    if (!ran) WARN("no OpenCL device with fp64: skipped");
}
