// --verify's comparison: agreement passes with exact counts, a wrong engine is caught.
#include <catch2/catch.hpp>

#include "formfactor/reference.h"
#include "formfactor/verify.h"
#include "mesh/mesh.h"
#include "test_scenes.h"

using namespace hemirad;

namespace {

mesh::Mesh box_mesh(scene::Scene& s) {
    const auto grey = test::add_material(s, glm::dvec3(0.5), glm::dvec3(1.0));
    s = test::closed_box({1.0, 0.8, 1.2}, [&](int) { return grey; }, s);
    return mesh::build(s, {0.4, 0.2});
}

}  // namespace

TEST_CASE("verify: an engine that agrees with the reference passes and is counted", "[verify]") {
    scene::Scene s;
    const mesh::Mesh m = box_mesh(s);
    formfactor::VerifyingEngine engine(std::make_unique<formfactor::ReferenceEngine>(m, formfactor::Settings{32, 3}),
                                       std::make_unique<formfactor::ReferenceEngine>(m, formfactor::Settings{32, 3}), 2);
    formfactor::ShotResult r;
    for (std::uint64_t shot = 0; shot < 10; ++shot) engine.shoot(static_cast<std::uint32_t>(shot % m.patches.size()), shot, r);
    const auto& sum = engine.summary();
    CHECK(sum.shots_checked == 5);  // shots 0, 2, 4, 6, 8
    CHECK(sum.cells_compared == 5L * 3 * 32 * 32);
    CHECK(sum.cells_mismatched == 0);
    CHECK(sum.max_abs_error == 0.0);
}

TEST_CASE("verify: an engine that disagrees stops the bake with the numbers", "[verify]") {
    scene::Scene s;
    const mesh::Mesh m = box_mesh(s);
    // Another seed rotates the hemicube differently: the ids and the form factors change.
    formfactor::VerifyingEngine engine(std::make_unique<formfactor::ReferenceEngine>(m, formfactor::Settings{32, 4}),
                                       std::make_unique<formfactor::ReferenceEngine>(m, formfactor::Settings{32, 3}), 1);
    formfactor::ShotResult r;
    try {
        engine.shoot(0, 0, r);
        FAIL("a wrong engine was not caught");
    } catch (const formfactor::VerifyError& e) {
        const std::string what = e.what();
        CHECK(what.find("shot 0") != std::string::npos);
        CHECK(what.find("the reference says") != std::string::npos);
        CHECK(engine.summary().cells_mismatched > 0);
    }
}
