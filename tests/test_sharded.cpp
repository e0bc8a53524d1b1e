// Several engines sharing each batch (formfactor::ShardedEngine) and what MPI ranks exchange
// (dist::pack_*): the rows are those of one engine bit for bit, whoever computed them, a faster
// member takes more shots, a member that may drop out and fails leaves its shots to the others,
// and a mesh, a batch of shots and their rows come back from their bytes exactly.
#include <catch2/catch.hpp>

#include <atomic>
#include <chrono>
#include <thread>

#include "backends.h"
#include "cl/runtime.h"
#include "core/error.h"
#include "dist/dist.h"
#include "formfactor/opencl_engine.h"
#include "formfactor/reference.h"
#include "formfactor/sharded.h"
#include "mesh/mesh.h"
#include "solve/progressive.h"
#include "test_scenes.h"

using namespace hemirad;

namespace {

mesh::Mesh lit_box() {
    scene::Scene s;
    const auto wall = test::add_material(s, glm::dvec3(0.7, 0.5, 0.4), glm::dvec3(0.0));
    const auto light = test::add_material(s, glm::dvec3(0.5), glm::dvec3(3.0, 2.0, 1.0));
    s = test::closed_box({1.0, 0.8, 1.2}, [&](int face) { return face == 3 ? light : wall; }, s);
    // An inner block, so that shots are occluded.
    s = test::closed_box({0.3, 0.3, 0.3}, [&](int) { return wall; }, s);
    return mesh::build(s, {0.3, 0.15});
}

// The reference engine, slowed per shot, failing from its `fail_from`-th call on with `Error`, and
// counting what it shot.
template <class Error = ocl::DeviceError>
class TestMember final : public formfactor::Engine {
public:
    TestMember(const mesh::Mesh& m, const formfactor::Settings& s, std::chrono::milliseconds per_shot = {},
               int fail_from = -1)
        : inner_(m, s), per_shot_(per_shot), fail_from_(fail_from) {}
    std::string name() const override { return "test"; }
    using formfactor::Engine::shoot;
    void shoot(const formfactor::ShotRequest& request, formfactor::ShotResult& out) override {
        if (fail_from_ >= 0 && calls_++ >= fail_from_) throw Error("the test member failed");
        std::this_thread::sleep_for(per_shot_);
        inner_.shoot(request, out);
        ++shots;
    }
    std::atomic<int> shots{0};

private:
    formfactor::ReferenceEngine inner_;
    std::chrono::milliseconds per_shot_;
    int fail_from_ = -1;
    int calls_ = 0;
};

std::vector<formfactor::ShotRequest> every_patch(const mesh::Mesh& m) {
    std::vector<formfactor::ShotRequest> shots;
    for (std::uint32_t p = 0; p < m.patches.size(); ++p) shots.push_back(formfactor::ShotRequest::of_patch(p, 7 * p + 1));
    return shots;
}

// What one reference engine shoots: the rows every sharing must reproduce.
std::vector<formfactor::ShotResult> reference_rows(const mesh::Mesh& m, const formfactor::Settings& settings,
                                                   const std::vector<formfactor::ShotRequest>& shots) {
    formfactor::ReferenceEngine one(m, settings);
    std::vector<formfactor::ShotResult> rows;
    one.shoot_batch(shots, rows);
    return rows;
}

std::string failure(const std::exception& e) {
    return dynamic_cast<const ocl::DeviceError*>(&e) ? std::string(e.what()) : std::string();
}

}  // namespace

TEST_CASE("sharded: the rows of a batch shared by several engines are one engine's, bit for bit", "[sharded]") {
    const mesh::Mesh m = lit_box();
    const formfactor::Settings settings{32, 3};
    const std::vector<formfactor::ShotRequest> shots = every_patch(m);
    REQUIRE(shots.size() > 40);
    const std::vector<formfactor::ShotResult> want = reference_rows(m, settings, shots);

    for (const std::size_t members : {2u, 3u}) {
        std::vector<formfactor::ShardedEngine::Member> list;
        for (std::size_t i = 0; i < members; ++i)
            list.push_back({std::make_unique<formfactor::ReferenceEngine>(m, settings), "ref " + std::to_string(i), false});
        auto stats = std::make_shared<formfactor::ShardStats>();
        formfactor::ShardedEngine sharded(std::move(list), failure, stats);
        std::vector<formfactor::ShotResult> got;
        sharded.shoot_batch(shots, got);
        CAPTURE(members);
        REQUIRE(got.size() == want.size());
        CHECK(got == want);
        long counted = 0;
        for (const auto& member : stats->members) counted += member.shots;
        CHECK(counted == static_cast<long>(shots.size()));
        // One shot at a time too.
        formfactor::ShotResult row;
        sharded.shoot(shots[5], row);
        CHECK(row == want[5]);
    }
}

TEST_CASE("sharded: a progressive solve on shared batches ends with the same bits as on one engine", "[sharded][solver]") {
    const mesh::Mesh m = lit_box();
    const formfactor::Settings settings{32, 3};
    solve::Settings solve_settings;
    solve_settings.batch = 8;
    solve_settings.threshold = 1e-3;
    formfactor::ReferenceEngine one(m, settings);
    solve::Progressive a(m, one, solve_settings);
    while (a.step()) {
    }
    std::vector<formfactor::ShardedEngine::Member> list;
    list.push_back({std::make_unique<formfactor::ReferenceEngine>(m, settings), "a", false});
    list.push_back({std::make_unique<TestMember<>>(m, settings, std::chrono::milliseconds(1)), "b", false});
    formfactor::ShardedEngine sharded(std::move(list), failure);
    solve::Progressive b(m, sharded, solve_settings);
    while (b.step()) {
    }
    CHECK(a.passes() == b.passes());
    CHECK(a.radiosity(true) == b.radiosity(true));
}

TEST_CASE("sharded: a faster member takes more of the batch", "[sharded]") {
    const mesh::Mesh m = lit_box();
    const formfactor::Settings settings{16, 3};
    const std::vector<formfactor::ShotRequest> shots = every_patch(m);
    auto slow = std::make_unique<TestMember<>>(m, settings, std::chrono::milliseconds(40));
    auto fast = std::make_unique<TestMember<>>(m, settings);
    TestMember<>* slow_p = slow.get();
    TestMember<>* fast_p = fast.get();
    std::vector<formfactor::ShardedEngine::Member> list;
    list.push_back({std::move(slow), "slow", false});
    list.push_back({std::move(fast), "fast", false});
    formfactor::ShardedEngine sharded(std::move(list), failure);
    std::vector<formfactor::ShotResult> got;
    sharded.shoot_batch(shots, got);
    // The slow member's first chunk (a quarter of the batch) takes it 40 ms a shot; the fast one
    // shoots everything else in that time.
    CAPTURE(slow_p->shots.load(), fast_p->shots.load());
    CHECK(slow_p->shots + fast_p->shots == static_cast<int>(shots.size()));
    CHECK(fast_p->shots > 2 * slow_p->shots);
}

TEST_CASE("sharded: a failing member that may drop out leaves its shots to the others, with the same rows", "[sharded]") {
    const mesh::Mesh m = lit_box();
    const formfactor::Settings settings{32, 3};
    const std::vector<formfactor::ShotRequest> shots = every_patch(m);
    const std::vector<formfactor::ShotResult> want = reference_rows(m, settings, shots);

    auto stats = std::make_shared<formfactor::ShardStats>();
    std::vector<formfactor::ShardedEngine::Member> list;
    list.push_back({std::make_unique<TestMember<>>(m, settings, std::chrono::milliseconds(1)), "steady", false});
    list.push_back({std::make_unique<TestMember<>>(m, settings, std::chrono::milliseconds(0), 3), "failing", true});
    formfactor::ShardedEngine sharded(std::move(list), failure, stats);
    std::vector<formfactor::ShotResult> got;
    sharded.shoot_batch(shots, got);
    CHECK(got == want);
    CHECK(sharded.live() == 1);
    REQUIRE(stats->members.size() == 2);
    CHECK(stats->members[0].dropped.empty());
    CHECK(stats->members[1].dropped == "the test member failed");
    CHECK(stats->members[0].shots + stats->members[1].shots == static_cast<long>(shots.size()));
    // The next batch goes to the one that is left.
    sharded.shoot_batch(shots, got);
    CHECK(got == want);
}

TEST_CASE("sharded: a failure ends the batch where the member may not drop, is the last, or is no device's", "[sharded]") {
    const mesh::Mesh m = lit_box();
    const formfactor::Settings settings{16, 3};
    const std::vector<formfactor::ShotRequest> shots = every_patch(m);
    std::vector<formfactor::ShotResult> got;
    {  // named by the user: its failure is the bake's
        std::vector<formfactor::ShardedEngine::Member> list;
        list.push_back({std::make_unique<formfactor::ReferenceEngine>(m, settings), "a", false});
        list.push_back({std::make_unique<TestMember<>>(m, settings, std::chrono::milliseconds(0), 0), "b", false});
        formfactor::ShardedEngine sharded(std::move(list), failure);
        CHECK_THROWS_AS(sharded.shoot_batch(shots, got), ocl::DeviceError);
    }
    {  // the last one left
        std::vector<formfactor::ShardedEngine::Member> list;
        list.push_back({std::make_unique<TestMember<>>(m, settings, std::chrono::milliseconds(0), 1), "a", true});
        list.push_back({std::make_unique<TestMember<>>(m, settings, std::chrono::milliseconds(0), 2), "b", true});
        formfactor::ShardedEngine sharded(std::move(list), failure);
        CHECK_THROWS_AS(sharded.shoot_batch(shots, got), ocl::DeviceError);
    }
    {  // a bug, not a device's failure
        std::vector<formfactor::ShardedEngine::Member> list;
        list.push_back({std::make_unique<formfactor::ReferenceEngine>(m, settings), "a", true});
        list.push_back({std::make_unique<TestMember<InternalError>>(m, settings, std::chrono::milliseconds(0), 0), "b", true});
        formfactor::ShardedEngine sharded(std::move(list), failure);
        CHECK_THROWS_AS(sharded.shoot_batch(shots, got), InternalError);
    }
}

TEST_CASE("sharded: the reference and an OpenCL device share a batch with the reference's bits", "[sharded][opencl]") {
    HEMIRAD_SKIP_ABSENT(test::first_opencl());
    const std::vector<ocl::DeviceInfo> devices = ocl::list_devices();
    const mesh::Mesh m = lit_box();
    const formfactor::Settings settings{64, 3};
    const std::vector<formfactor::ShotRequest> shots = every_patch(m);
    const std::vector<formfactor::ShotResult> want = reference_rows(m, settings, shots);
    ocl::Context context(devices.front());
    std::vector<formfactor::ShardedEngine::Member> list;
    list.push_back({std::make_unique<formfactor::ReferenceEngine>(m, settings), "ref", false});
    list.push_back({std::make_unique<formfactor::OpenCLEngine>(m, context, settings), devices.front().id(), false});
    auto stats = std::make_shared<formfactor::ShardStats>();
    formfactor::ShardedEngine sharded(std::move(list), failure, stats);
    std::vector<formfactor::ShotResult> got;
    sharded.shoot_batch(shots, got);
    CHECK(got == want);
    CHECK(stats->members[0].shots > 0);
    CHECK(stats->members[1].shots > 0);
}

TEST_CASE("dist: a mesh, a batch of shots and their rows come back from their bytes exactly", "[sharded][dist]") {
    const mesh::Mesh m = lit_box();
    const std::string bytes = dist::pack_mesh(m);
    const mesh::Mesh back = dist::unpack_mesh(bytes);
    CHECK(dist::pack_mesh(back) == bytes);
    REQUIRE(back.elements.size() == m.elements.size());
    REQUIRE(back.patches.size() == m.patches.size());
    CHECK(back.elements.back().poly.v[2] == m.elements.back().poly.v[2]);
    CHECK(back.patches.front().twin == m.patches.front().twin);
    // The unpacked mesh shoots the same rows.
    const formfactor::Settings settings{32, 9};
    formfactor::ReferenceEngine a(m, settings), b(back, settings);
    const std::vector<formfactor::ShotRequest> shots = every_patch(m);
    std::vector<formfactor::ShotResult> ra, rb;
    a.shoot_batch(shots, ra);
    b.shoot_batch(shots, rb);
    CHECK(ra == rb);

    std::uint64_t id = 0;
    std::vector<formfactor::ShotRequest> mixed = shots;
    mixed.push_back(formfactor::ShotRequest::of_light(2, 99));
    mixed.push_back(formfactor::ShotRequest::of_point(5, 1ull << 40));
    const std::vector<formfactor::ShotRequest> shots_back = dist::unpack_shots(dist::pack_shots(42, mixed), id);
    CHECK(id == 42);
    REQUIRE(shots_back.size() == mixed.size());
    for (std::size_t i = 0; i < mixed.size(); ++i) {
        CHECK(shots_back[i].shooter == mixed[i].shooter);
        CHECK(shots_back[i].shot == mixed[i].shot);
    }
    ra.front().blocked = 0.125;
    CHECK(dist::unpack_rows(dist::pack_rows(ra)) == ra);
    // Cut short or padded: refused.
    const std::string rows = dist::pack_rows(ra);
    CHECK_THROWS_AS(dist::unpack_rows(rows.substr(0, rows.size() - 3)), InternalError);
    CHECK_THROWS_AS(dist::unpack_rows(rows + "x"), InternalError);
    CHECK_THROWS_AS(dist::unpack_mesh(bytes.substr(0, bytes.size() / 2)), InternalError);
}
