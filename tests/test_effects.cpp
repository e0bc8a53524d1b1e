// The effects planner (what a scene calls for) and the occlusion-free analytic engine.
#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>
#include <stdexcept>

#include "formfactor/analytic.h"
#include "formfactor/reference.h"
#include "formfactor/unoccluded.h"
#include "mesh/mesh.h"
#include "scene/effects.h"
#include "solve/matrix.h"
#include "solve/progressive.h"
#include "test_scenes.h"

using namespace hemirad;
using Catch::Matchers::Contains;
using Catch::Matchers::WithinAbs;
using Catch::Matchers::WithinRel;

namespace {

const std::filesystem::path kSourceDir = HEMIRAD_SOURCE_DIR;

scene::Scene grey_scene(std::uint32_t& grey, std::uint32_t& light) {
    scene::Scene s;
    grey = test::add_material(s, glm::dvec3(0.5), glm::dvec3(0.0));
    light = test::add_material(s, glm::dvec3(0.5), glm::dvec3(1.0));
    return s;
}

scene::Scene unit_box(std::uint32_t& grey, std::uint32_t& light) {
    scene::Scene base = grey_scene(grey, light);
    const std::uint32_t g = grey, l = light;
    return test::closed_box(glm::dvec3(1.0), [g, l](int face) { return face == 3 ? l : g; }, base);
}

// A small cube [lo, hi]³ whose six faces look outwards, one node per face ("block-x" ...).
void add_block(scene::Scene& s, glm::dvec3 lo, glm::dvec3 hi, std::uint32_t material) {
    const double x0 = lo.x, y0 = lo.y, z0 = lo.z, x1 = hi.x, y1 = hi.y, z1 = hi.z;
    test::add_quad(s, {x0, y0, z0}, {x0, y0, z1}, {x0, y1, z1}, {x0, y1, z0}, material, "block-x");  // normal −x
    test::add_quad(s, {x1, y0, z0}, {x1, y1, z0}, {x1, y1, z1}, {x1, y0, z1}, material, "block+x");  // normal +x
    test::add_quad(s, {x0, y0, z0}, {x1, y0, z0}, {x1, y0, z1}, {x0, y0, z1}, material, "block-y");  // normal −y
    test::add_quad(s, {x0, y1, z0}, {x0, y1, z1}, {x1, y1, z1}, {x1, y1, z0}, material, "block+y");  // normal +y
    test::add_quad(s, {x0, y0, z0}, {x0, y1, z0}, {x1, y1, z0}, {x1, y0, z0}, material, "block-z");  // normal −z
    test::add_quad(s, {x0, y0, z1}, {x1, y0, z1}, {x1, y1, z1}, {x0, y1, z1}, material, "block+z");  // normal +z
    test::finish(s);
}

// Independent reference for one element: F(shooter → element) = A_e / A_s × the mean over the
// element of F(dA_x → shooter), by a q×q midpoint rule on the element's bilinear map (Jacobian
// weighted), every point evaluated (no distance-based order, no culling).
double direct_element_ff(const mesh::Element& e, const mesh::Patch& shooter, int q) {
    REQUIRE(e.poly.n == 4);
    const auto& v = e.poly.v;
    double sum = 0.0, weight = 0.0;
    for (int b = 0; b < q; ++b)
        for (int a = 0; a < q; ++a) {
            const double u = (a + 0.5) / q, w = (b + 0.5) / q;
            const glm::dvec3 x = (1 - u) * (1 - w) * v[0] + u * (1 - w) * v[1] + u * w * v[2] + (1 - u) * w * v[3];
            const glm::dvec3 du = (1 - w) * (v[1] - v[0]) + w * (v[2] - v[3]);
            const glm::dvec3 dw = (1 - u) * (v[3] - v[0]) + u * (v[2] - v[1]);
            const double jac = glm::length(glm::cross(du, dw));
            const double f = glm::dot(shooter.normal, x - shooter.centroid) > 0.0
                                 ? formfactor::point_to_polygon(x, e.normal, shooter.poly)
                                 : 0.0;
            sum += jac * f;
            weight += jac;
        }
    return e.area / shooter.area * sum / weight;
}

// Checks every element's F from `patch` against the direct quadrature; returns the worst
// relative error over the elements that receive anything.
double worst_element_error(const mesh::Mesh& m, formfactor::Engine& engine, std::uint32_t patch) {
    formfactor::ShotResult r;
    engine.shoot(patch, 0, r);
    const std::vector<double> F = r.dense(m.elements.size());
    CHECK(r.blocked == 0.0);
    double worst = 0.0;
    for (std::size_t k = 0; k < m.elements.size(); ++k) {
        const mesh::Element& e = m.elements[k];
        if (e.node == m.patches[patch].node) {
            CHECK(F[k] == 0.0);  // coplanar with the shooter
            continue;
        }
        const double direct = direct_element_ff(e, m.patches[patch], 64);
        REQUIRE(direct > 0.0);
        worst = std::max(worst, std::abs(F[k] - direct) / direct);
    }
    return worst;
}

}  // namespace

// ---- planner ---------------------------------------------------------------------------------

TEST_CASE("effects: occlusion is off for convex arrangements", "[effects]") {
    std::uint32_t grey = 0, light = 0;
    const scene::Scene base = grey_scene(grey, light);
    SECTION("parallel squares facing each other") {
        const scene::Scene s = test::parallel_rectangles(1, 1, 1, grey, light, base);
        const scene::EffectsPlan plan = scene::plan_effects(s, {});
        CHECK_FALSE(plan.occlusion.on);
        CHECK_FALSE(plan.occlusion.forced);
        CHECK_THAT(plan.occlusion.why, Contains("convex"));
    }
    SECTION("perpendicular squares sharing an edge") {
        const scene::Scene s = test::perpendicular_rectangles(1, 1, 1, grey, light, base);
        CHECK_FALSE(scene::plan_effects(s, {}).occlusion.on);
    }
    SECTION("an empty closed box") {
        const scene::Scene s = unit_box(grey, light);
        const scene::EffectsPlan plan = scene::plan_effects(s, {});
        CHECK_FALSE(plan.occlusion.on);
        CHECK_THAT(plan.occlusion.why, Contains("8 vertices") && Contains("6 distinct"));
    }
}

TEST_CASE("effects: a block inside a box needs occlusion and the reason names it", "[effects]") {
    std::uint32_t grey = 0, light = 0;
    scene::Scene s = unit_box(grey, light);
    add_block(s, glm::dvec3(0.4), glm::dvec3(0.6), grey);
    const scene::EffectsPlan plan = scene::plan_effects(s, {});
    CHECK(plan.occlusion.on);
    CHECK_FALSE(plan.occlusion.forced);
    CHECK_THAT(plan.occlusion.why, Contains("behind the plane of triangle") && Contains("'block"));
}

TEST_CASE("effects: see-through surfaces are left out, and the other effects judged without them", "[effects]") {
    std::uint32_t grey = 0, light = 0;
    scene::Scene s = unit_box(grey, light);
    const std::size_t box_triangles = s.triangles.size();
    const std::uint32_t glass = test::add_material(s, glm::dvec3(0.9), glm::dvec3(0.0));
    s.materials[glass].name = "glass";
    s.materials[glass].see_through = "alphaMode BLEND, mean opacity 0.20";
    add_block(s, glm::dvec3(0.4), glm::dvec3(0.6), glass);  // a glass block inside the box

    const scene::EffectsPlan plan = scene::plan_effects(s, {});
    CAPTURE(plan.see_through.why, plan.occlusion.why);
    CHECK(plan.see_through.on);
    CHECK_FALSE(plan.see_through.forced);
    CHECK_THAT(plan.see_through.why, Contains("12 of 24 triangles") && Contains("'glass'") &&
                                          Contains("alphaMode BLEND") && Contains("see_through=off"));
    CHECK_FALSE(plan.occlusion.on);  // the empty box is convex: the block does not count
    scene::Scene meshed = s;
    scene::apply_see_through(meshed, plan);
    CHECK(meshed.triangles.size() == box_triangles);
    for (const scene::Triangle& t : meshed.triangles) CHECK(t.material != glass);

    // Forced off: the block is an opaque surface, which hides parts of the box from others.
    scene::EffectOverrides opaque;
    opaque.see_through = scene::Force::off;
    const scene::EffectsPlan forced = scene::plan_effects(s, opaque);
    CHECK_FALSE(forced.see_through.on);
    CHECK(forced.see_through.forced);
    CHECK(forced.occlusion.on);
    scene::Scene kept = s;
    scene::apply_see_through(kept, forced);
    CHECK(kept.triangles.size() == s.triangles.size());

    // A scene without any: nothing to leave out.
    std::uint32_t g2 = 0, l2 = 0;
    const scene::EffectsPlan none = scene::plan_effects(unit_box(g2, l2), {});
    CHECK_FALSE(none.see_through.on);
    CHECK_THAT(none.see_through.why, Contains("every surface is opaque"));
    CHECK(scene::parse_effect_overrides("see_through=off").see_through == scene::Force::off);
}

TEST_CASE("effects: the Cornell box", "[effects]") {
    const scene::Scene s = scene::load(kSourceDir / "scenes" / "cornell_box.gltf");
    const scene::EffectsPlan plan = scene::plan_effects(s, {});
    CAPTURE(plan.occlusion.why, plan.colour.why, plan.interreflection.why, plan.two_sided.why);
    CHECK(plan.occlusion.on);
    CHECK_THAT(plan.occlusion.why, Contains("behind the plane of triangle"));
    CHECK(plan.colour.on);
    CHECK_THAT(plan.colour.why, Contains("material '"));
    CHECK(plan.interreflection.on);
    CHECK_FALSE(plan.two_sided.on);
    CHECK(plan.refinement.on);
    CHECK(plan.convergence.on);
    for (const scene::EffectDecision* d : {&plan.occlusion, &plan.colour, &plan.interreflection, &plan.two_sided,
                                           &plan.refinement, &plan.convergence}) {
        CHECK_FALSE(d->forced);
        CHECK_FALSE(d->why.empty());
    }
}

TEST_CASE("effects: colour, interreflection and two-sidedness from materials", "[effects]") {
    std::uint32_t grey = 0, light = 0;
    SECTION("a grey scene solves one channel") {
        const scene::Scene s = unit_box(grey, light);
        const scene::EffectsPlan plan = scene::plan_effects(s, {});
        CHECK_FALSE(plan.colour.on);
        CHECK(plan.interreflection.on);
        CHECK_FALSE(plan.two_sided.on);
    }
    SECTION("a coloured emitter alone needs colour") {
        scene::Scene base = grey_scene(grey, light);
        const std::uint32_t warm = test::add_material(base, glm::dvec3(0.5), glm::dvec3(1.0, 0.8, 0.6));
        const scene::Scene s = test::parallel_rectangles(1, 1, 1, grey, warm, base);
        const scene::EffectsPlan plan = scene::plan_effects(s, {});
        CHECK(plan.colour.on);
        CHECK_THAT(plan.colour.why, Contains("'m2'") && Contains("emits"));
    }
    SECTION("a coloured vertex reflectance needs colour") {
        scene::Scene s = unit_box(grey, light);
        s.triangles[5].rho[1] = glm::dvec3(0.5, 0.5, 0.4);
        const scene::EffectsPlan plan = scene::plan_effects(s, {});
        CHECK(plan.colour.on);
        CHECK_THAT(plan.colour.why, Contains("triangle 5"));
    }
    SECTION("every reflectance 0: no interreflection") {
        scene::Scene base;
        const std::uint32_t black = test::add_material(base, glm::dvec3(0.0), glm::dvec3(0.0));
        const std::uint32_t lamp = test::add_material(base, glm::dvec3(0.0), glm::dvec3(2.0));
        const scene::Scene s = test::parallel_rectangles(1, 1, 1, black, lamp, base);
        const scene::EffectsPlan plan = scene::plan_effects(s, {});
        CHECK_FALSE(plan.interreflection.on);
        CHECK_THAT(plan.interreflection.why, Contains("all 4 triangles"));
        CHECK_FALSE(plan.colour.on);
    }
    SECTION("a double-sided material: two-sided, and occlusion for the back faces") {
        scene::Scene base = grey_scene(grey, light);
        const std::uint32_t both = test::add_material(base, glm::dvec3(0.5), glm::dvec3(0.0), true);
        scene::Scene s = test::parallel_rectangles(1, 1, 1, both, light, base);
        scene::EffectsPlan plan = scene::plan_effects(s, {});
        CHECK(plan.two_sided.on);
        CHECK_THAT(plan.two_sided.why, Contains("'m2'"));
        CHECK(plan.occlusion.on);
        CHECK_THAT(plan.occlusion.why, Contains("back faces"));

        // Forced off: the back faces go, and the geometry alone decides occlusion.
        const scene::EffectOverrides off = scene::parse_effect_overrides("two_sided=off");
        plan = scene::plan_effects(s, off);
        CHECK_FALSE(plan.two_sided.on);
        CHECK(plan.two_sided.forced);
        CHECK_FALSE(plan.occlusion.on);
        scene::Scene copy = s;
        scene::apply_two_sided(copy, plan, off);
        for (const scene::Material& m : copy.materials) CHECK_FALSE(m.double_sided);
    }
    SECTION("two-sided forced on makes every material double-sided") {
        const scene::Scene base = grey_scene(grey, light);
        const scene::Scene s = test::parallel_rectangles(1, 1, 1, grey, light, base);
        const scene::EffectOverrides on = scene::parse_effect_overrides("two_sided=on");
        const scene::EffectsPlan plan = scene::plan_effects(s, on);
        CHECK(plan.two_sided.on);
        CHECK(plan.occlusion.on);
        scene::Scene copy = s;
        scene::apply_two_sided(copy, plan, on);
        for (const scene::Material& m : copy.materials) CHECK(m.double_sided);
        // Automatic leaves the materials alone.
        scene::Scene same = s;
        scene::apply_two_sided(same, scene::plan_effects(s, {}), {});
        for (std::size_t i = 0; i < s.materials.size(); ++i)
            CHECK(same.materials[i].double_sided == s.materials[i].double_sided);
    }
}

TEST_CASE("effects: colour off solves the luminance and leaves a grey scene as it is", "[effects]") {
    scene::Scene cornell = scene::load(kSourceDir / "scenes" / "cornell_box.gltf");
    const scene::Scene original = cornell;
    scene::EffectOverrides forced;
    forced.colour = scene::Force::off;
    scene::apply_colour(cornell, scene::plan_effects(cornell, forced));
    for (std::size_t t = 0; t < cornell.triangles.size(); ++t) {
        for (int k = 0; k < 3; ++k) {
            const glm::dvec3 was = original.triangles[t].rho[std::size_t(k)];
            const glm::dvec3 now = cornell.triangles[t].rho[std::size_t(k)];
            CHECK(now.x == now.y);
            CHECK(now.y == now.z);
            CHECK(now.x == Approx(0.2126 * was.x + 0.7152 * was.y + 0.0722 * was.z).epsilon(1e-12));
        }
    }
    const scene::Scene room = scene::load(kSourceDir / "scenes" / "empty_room.gltf");
    scene::Scene copy = room;
    const scene::EffectsPlan plan = scene::plan_effects(copy, {});
    REQUIRE_FALSE(plan.colour.on);
    scene::apply_colour(copy, plan);
    for (std::size_t t = 0; t < room.triangles.size(); ++t) CHECK(copy.triangles[t].rho == room.triangles[t].rho);
    for (std::size_t m = 0; m < room.materials.size(); ++m) CHECK(copy.materials[m].emission == room.materials[m].emission);
}

TEST_CASE("effects: overrides parse and force decisions", "[effects]") {
    const scene::EffectOverrides o = scene::parse_effect_overrides(" occlusion=off, colour = ON ,refinement=auto");
    CHECK(o.occlusion == scene::Force::off);
    CHECK(o.colour == scene::Force::on);
    CHECK(o.refinement == scene::Force::automatic);
    CHECK(o.interreflection == scene::Force::automatic);
    CHECK(o.two_sided == scene::Force::automatic);
    CHECK(o.convergence == scene::Force::automatic);
    const scene::EffectOverrides all = scene::parse_effect_overrides(
        "interreflection=off,two_sided=on,convergence=off,refinement=off,occlusion=on,colour=off");
    CHECK(all.interreflection == scene::Force::off);
    CHECK(all.two_sided == scene::Force::on);
    CHECK(all.convergence == scene::Force::off);
    CHECK(all.refinement == scene::Force::off);
    CHECK(all.occlusion == scene::Force::on);
    CHECK(all.colour == scene::Force::off);
    const scene::EffectOverrides none = scene::parse_effect_overrides("");
    CHECK(none.occlusion == scene::Force::automatic);

    std::uint32_t grey = 0, light = 0;
    scene::Scene s = unit_box(grey, light);
    add_block(s, glm::dvec3(0.4), glm::dvec3(0.6), grey);
    const scene::EffectsPlan plan = scene::plan_effects(s, o);
    CHECK_FALSE(plan.occlusion.on);
    CHECK(plan.occlusion.forced);
    CHECK_THAT(plan.occlusion.why, Contains("forced off from the command line") && Contains("would have turned it on") &&
                                       Contains("'block"));
    CHECK(plan.colour.on);
    CHECK(plan.colour.forced);
    CHECK_THAT(plan.colour.why, Contains("forced on") && Contains("would have turned it off"));
    CHECK(plan.refinement.on);
    CHECK_FALSE(plan.refinement.forced);
}

TEST_CASE("effects: bad override strings throw naming the item", "[effects]") {
    auto message = [](const std::string& spec) {
        try {
            scene::parse_effect_overrides(spec);
        } catch (const std::invalid_argument& e) {
            return std::string(e.what());
        }
        return std::string("no exception");
    };
    CHECK_THAT(message("occlusion"), Contains("'occlusion'") && Contains("name=on|off|auto"));
    CHECK_THAT(message("shadows=on"), Contains("unknown effect 'shadows'"));
    CHECK_THAT(message("colour=maybe"), Contains("bad value 'maybe'"));
    CHECK_THAT(message("colour=on,,occlusion=off"), Contains("empty item"));
    CHECK_THAT(message("colour=on,"), Contains("empty item"));
    CHECK_THAT(message("colour=on,colour=off"), Contains("'colour' given twice"));
    CHECK_THAT(message("=on"), Contains("unknown effect ''"));
}

// ---- the analytic engine ---------------------------------------------------------------------

TEST_CASE("effects: analytic engine matches closed-form rectangle form factors", "[effects]") {
    std::uint32_t grey = 0, light = 0;
    const scene::Scene base = grey_scene(grey, light);
    struct Case {
        const char* name;
        scene::Scene scene;
        double exact;
    };
    const Case cases[] = {
        {"perpendicular unit squares", test::perpendicular_rectangles(1, 1, 1, grey, grey, base),
         test::perpendicular_rectangles_ff(1, 1, 1)},
        {"parallel unit squares 1 apart", test::parallel_rectangles(1, 1, 1, grey, grey, base),
         test::parallel_rectangles_ff(1, 1, 1)},
        {"parallel unit squares 0.25 apart", test::parallel_rectangles(1, 1, 0.25, grey, grey, base),
         test::parallel_rectangles_ff(1, 1, 0.25)},
    };
    for (const Case& c : cases) {
        CAPTURE(c.name);
        REQUIRE_FALSE(scene::plan_effects(c.scene, {}).occlusion.on);
        const mesh::Mesh m = mesh::build(c.scene, {1.0 / 8, 1.0 / 24});
        REQUIRE(m.patches.size() == 128);
        REQUIRE(m.elements.size() == 2 * 576);
        formfactor::UnoccludedEngine engine(m);
        CHECK(engine.name() == "analytic");
        const double f01 = test::area_form_factor(m, engine, 0, 1);
        const double f10 = test::area_form_factor(m, engine, 1, 0);
        const double err01 = std::abs(f01 - c.exact) / c.exact, err10 = std::abs(f10 - c.exact) / c.exact;
        CAPTURE(f01, f10, c.exact, err01, err10);
        CHECK(err01 < 0.002);
        CHECK(err10 < 0.002);

        // Every element from a corner patch, one on the middle of the edge, and a central one.
        double worst = 0.0;
        for (std::uint32_t p = 0; p < m.patches.size(); ++p) {
            if (m.patches[p].node != 0) continue;
            const glm::dvec3 c0 = m.patches[p].centroid;
            const bool corner = c0.x < 0.1 && c0.y < 0.1;
            const bool edge = std::abs(c0.x - 0.5625) < 1e-9 && c0.y < 0.1;
            const bool middle = std::abs(c0.x - 0.5625) < 1e-9 && std::abs(c0.y - 0.5625) < 1e-9;
            if (corner || edge || middle) worst = std::max(worst, worst_element_error(m, engine, p));
        }
        CAPTURE(worst);
        CHECK(worst < 0.005);
    }
}

TEST_CASE("effects: analytic engine closes the box", "[effects]") {
    std::uint32_t grey = 0, light = 0;
    const scene::Scene s = unit_box(grey, light);
    const mesh::Mesh m = mesh::build(s, {1.0 / 8, 1.0 / 24});
    formfactor::UnoccludedEngine engine(m);
    formfactor::ShotResult r;
    double worst = 0.0;
    for (std::uint32_t p = 0; p < m.patches.size(); ++p) {
        engine.shoot(p, p, r);
        double sum = 0.0;
        for (double f : r.F) sum += f;
        worst = std::max(worst, std::abs(sum - 1.0));
        CHECK(r.blocked == 0.0);
    }
    // Every point of a shooter sees the box's other walls tile its hemisphere, so the rows,
    // scaled to the total seen from the shooter's side, sum to 1 to rounding (the receiver-side
    // rule alone was 1.4e-4 over: 16% at ρ = 0.999 once 1/(1 − ρ) amplifies it).
    CAPTURE(worst);
    CHECK(worst < 1e-12);
}

TEST_CASE("effects: a face duplicated in place, or a decal on a wall, keeps occlusion on", "[effects]") {
    std::uint32_t grey = 0, light = 0;
    scene::Scene s = unit_box(grey, light);
    // Each wall is two triangles sharing a diagonal: touching along an edge is no overlap.
    REQUIRE_FALSE(scene::plan_effects(s, {}).occlusion.on);
    // A decal: a smaller quad on the floor (z = 0, facing +z), facing the same way.
    test::add_quad(s, {0.2, 0.2, 0}, {0.5, 0.2, 0}, {0.5, 0.5, 0}, {0.2, 0.5, 0}, grey, "decal");
    test::finish(s);
    const scene::EffectsPlan plan = scene::plan_effects(s, {});
    CHECK(plan.occlusion.on);
    CHECK_THAT(plan.occlusion.why, Contains("overlap in one plane") && Contains("'decal'"));
}

TEST_CASE("effects: analytic engine is deterministic and ignores the shot counter", "[effects]") {
    std::uint32_t grey = 0, light = 0;
    const scene::Scene base = grey_scene(grey, light);
    const scene::Scene s = test::perpendicular_rectangles(1, 1, 1, grey, grey, base);
    const mesh::Mesh m = mesh::build(s, {0.25, 0.125});
    formfactor::UnoccludedEngine engine(m);
    formfactor::ShotResult a, b;
    engine.shoot(3, 0, a);
    engine.shoot(3, 12345, b);
    CHECK(a == b);
    std::vector<formfactor::ShotResult> batch;
    engine.shoot_batch({formfactor::ShotRequest::of_patch(3, 7), formfactor::ShotRequest::of_patch(5, 8)}, batch);
    REQUIRE(batch.size() == 2);
    CHECK(batch[0] == a);
    // A batch runs on the machine's threads: every patch at once, each row shoot()'s bit for bit,
    // in the batch's order.
    std::vector<formfactor::ShotRequest> all;
    for (std::uint32_t p = 0; p < m.patches.size(); ++p) all.push_back(formfactor::ShotRequest::of_patch(p, p));
    engine.shoot_batch(all, batch);
    REQUIRE(batch.size() == m.patches.size());
    REQUIRE(m.patches.size() > 8);
    for (std::uint32_t p = 0; p < m.patches.size(); ++p) {
        formfactor::ShotResult one;
        engine.shoot(p, 0, one);
        INFO("patch " << p);
        CHECK(batch[p] == one);
    }
    CHECK(formfactor::UnoccludedEngine::subdivisions(5.0, 1.0) == 1);
    CHECK(formfactor::UnoccludedEngine::subdivisions(3.0, 1.0) == 2);
    CHECK(formfactor::UnoccludedEngine::subdivisions(1.5, 1.0) == 4);
    CHECK(formfactor::UnoccludedEngine::subdivisions(1.0, 1.0) == 8);
}

TEST_CASE("effects: a scene that reflects nothing needs only its lamps' shots", "[effects]") {
    // A lamp (ρ = 0) above a black floor with a black block between them: interreflection is
    // planned off. Solving it with bounces anyway (the matrix solver, every patch that could
    // hold light) shoots the same rows and gives the same numbers, bit for bit; the progressive
    // solver, which shoots only what holds unshot light, shoots the lamps alone too.
    scene::Scene s;
    const std::uint32_t lamp = scene::add_material(s, glm::dvec3(0.0), glm::dvec3(1.0));
    const std::uint32_t black = scene::add_material(s, glm::dvec3(0.0), glm::dvec3(0.0));
    scene::add_quad(s, {-2, -2, 0}, {2, -2, 0}, {2, 2, 0}, {-2, 2, 0}, black, "floor");
    add_block(s, {-0.3, -0.3, 0.5}, {0.3, 0.3, 0.8}, black);
    scene::add_quad(s, {-0.5, -0.5, 2}, {-0.5, 0.5, 2}, {0.5, 0.5, 2}, {0.5, -0.5, 2}, lamp, "lamp");
    scene::finish(s);
    const scene::EffectsPlan plan = scene::plan_effects(s, {});
    CHECK_FALSE(plan.interreflection.on);
    CHECK(plan.occlusion.on);

    const mesh::Mesh m = mesh::build(s, {0.5, 0.25});
    std::uint32_t lamp_patches = 0;
    for (const mesh::Patch& p : m.patches) lamp_patches += p.emission.x > 0.0 ? 1 : 0;
    formfactor::ReferenceEngine engine(m, {64, 1});
    solve::MatrixSettings direct;
    direct.interreflection = false;
    solve::Matrix planned(m, engine, direct);
    planned.solve();
    solve::Matrix bounced(m, engine, {});
    bounced.solve();
    CHECK(planned.rows() == lamp_patches);
    CHECK(bounced.rows() == lamp_patches);
    CHECK(planned.radiosity() == bounced.radiosity());
    CHECK(planned.irradiance() == bounced.irradiance());

    solve::Settings settings;
    settings.threshold = 0.0;
    solve::Progressive progressive(m, engine, settings);
    while (progressive.step()) {
    }
    CHECK(progressive.passes() == lamp_patches);
    // Its hemicubes turn by other angles (its shot counter is the pass), so the flux agrees to
    // the hemicube's noise, not bit for bit.
    double flux_progressive = 0.0, flux_matrix = 0.0;
    const std::vector<glm::dvec3> H = progressive.irradiance(false);
    for (std::size_t k = 0; k < H.size(); ++k) {
        flux_progressive += H[k].x * m.elements[k].area;
        flux_matrix += planned.irradiance()[k].x * m.elements[k].area;
    }
    CHECK_THAT(flux_progressive, Catch::WithinRel(flux_matrix, 1e-3));
}
