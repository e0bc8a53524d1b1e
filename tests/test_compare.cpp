// The engines' comparison scenes and the comparison itself (see test_compare.h).
#include "test_compare.h"

#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>

#include "gen/procedural.h"
#include "test_scenes.h"

namespace hemirad::test {

void add_block(scene::Scene& s, glm::dvec3 lo, glm::dvec3 hi, std::uint32_t material, const std::string& name) {
    const double x0 = lo.x, y0 = lo.y, z0 = lo.z, x1 = hi.x, y1 = hi.y, z1 = hi.z;
    add_quad(s, {x0, y0, z1}, {x1, y0, z1}, {x1, y1, z1}, {x0, y1, z1}, material, name + "_top");  // +z
    add_quad(s, {x0, y0, z0}, {x1, y0, z0}, {x1, y0, z1}, {x0, y0, z1}, material, name + "_y0");   // -y
    add_quad(s, {x1, y1, z0}, {x0, y1, z0}, {x0, y1, z1}, {x1, y1, z1}, material, name + "_y1");   // +y
    add_quad(s, {x0, y1, z0}, {x0, y0, z0}, {x0, y0, z1}, {x0, y1, z1}, material, name + "_x0");   // -x
    add_quad(s, {x1, y0, z0}, {x1, y1, z0}, {x1, y1, z1}, {x1, y0, z1}, material, name + "_x1");   // +x
}

std::vector<Case> comparison_cases() {
    std::vector<Case> cases;
    {
        scene::Scene s;
        const auto grey = add_material(s, glm::dvec3(0.5), glm::dvec3(0.0));
        cases.push_back({"closed box",
                         closed_box(
                             {1.0, 0.8, 1.2}, [&](int) { return grey; }, s),
                         {0.25, 0.125}});
    }
    {
        scene::Scene s;
        const auto grey = add_material(s, glm::dvec3(0.5), glm::dvec3(0.0));
        cases.push_back({"perpendicular rectangles", perpendicular_rectangles(1, 1, 1, grey, grey, s), {0.25, 0.125}});
    }
    {
        scene::Scene s;
        const auto grey = add_material(s, glm::dvec3(0.5), glm::dvec3(0.0));
        const auto two_sided = add_material(s, glm::dvec3(0.5), glm::dvec3(0.0), true);
        s = parallel_rectangles(1, 1, 1, grey, grey, s);
        // Facing up: the lower rectangle sees its back (a blocker), the upper its front.
        add_quad(s, {0.2, 0.2, 0.4}, {0.6, 0.2, 0.4}, {0.6, 0.6, 0.4}, {0.2, 0.6, 0.4}, grey, "one_sided");
        // Both sides are surfaces: no blocker, the twin is drawn instead.
        add_quad(s, {0.4, 0.4, 0.6}, {0.4, 0.8, 0.6}, {0.8, 0.8, 0.6}, {0.8, 0.4, 0.6}, two_sided, "two_sided");
        // The same quad twice (z-fighting): every cell is a genuine depth tie, won by the lower index.
        for (const char* name : {"copy_a", "copy_b"})
            add_quad(s, {0.1, 0.5, 0.8}, {0.1, 0.9, 0.8}, {0.5, 0.9, 0.8}, {0.5, 0.5, 0.8}, grey, name);
        finish(s);
        cases.push_back({"occluders", s, {0.2, 0.1}});
    }
    {
        scene::Scene s;
        const auto white = add_material(s, glm::dvec3(0.7), glm::dvec3(0.0));
        const auto light = add_material(s, glm::dvec3(0.5), glm::dvec3(5.0));
        s = closed_box(
            {1.0, 1.0, 1.0}, [&](int) { return white; }, s);
        add_quad(s, {0.4, 0.4, 0.99}, {0.4, 0.6, 0.99}, {0.6, 0.6, 0.99}, {0.6, 0.4, 0.99}, light, "light");
        add_block(s, {0.15, 0.2, 0.0}, {0.45, 0.5, 0.6}, white, "tall");
        add_block(s, {0.55, 0.5, 0.0}, {0.85, 0.8, 0.3}, white, "short");
        // Triangle elements (setup_lanes repeats their last vertex), one across the middle.
        add_triangle(s, {0.1, 0.9, 0.7}, {0.9, 0.9, 0.7}, {0.5, 0.1, 0.75}, white, "wedge");
        finish(s);
        cases.push_back({"cornell-like box", s, {0.2, 0.1}});
    }
    // A room of tessellated objects: most shooters stand on an object with half the scene or
    // more behind them, which the OpenCL setup culls a group of elements at a time.
    cases.push_back({"procedural objects", gen::procedural_scene(3000), {2.0, 1.0}});
    return cases;
}

Comparison compare(const mesh::Mesh& m, formfactor::ReferenceEngine& ref, formfactor::Engine& other, int shots) {
    Comparison c;
    formfactor::ShotResult a, b;
    const std::size_t patches = m.patches.size();
    for (int i = 0; i < shots; ++i) {
        const auto patch = static_cast<std::uint32_t>((static_cast<std::size_t>(i) * 7919u + 3u) % patches);
        const std::uint64_t shot = 1000u + static_cast<std::uint64_t>(i);
        ref.shoot(patch, shot, a);
        other.shoot(patch, shot, b);
        const auto& ids_ref = ref.ids();
        const auto& ids_cl = *other.last_ids();
        REQUIRE(ids_ref.size() == ids_cl.size());
        for (std::size_t cell = 0; cell < ids_ref.size(); ++cell) {
            c.mismatched_cells += ids_ref[cell] != ids_cl[cell];
            c.hit_cells += ids_ref[cell] >= 0;
            c.blocker_cells += ids_ref[cell] == formfactor::ReferenceEngine::kBlocker;
        }
        c.cells += ids_ref.size();
        ++c.shots;
        const auto note = [&c](double expected, double got) {
            const double err = std::abs(expected - got);
            if (err > 1e-6) c.worst_f = std::max(c.worst_f, err / std::max(std::abs(expected), 1e-300));
        };
        double total_a = a.blocked, total_b = b.blocked, l1 = std::abs(a.blocked - b.blocked);
        note(a.blocked, b.blocked);
        formfactor::for_each_in_union(a, b, [&](std::uint32_t, double fa, double fb) {
            note(fa, fb);
            total_a += fa;
            total_b += fb;
            l1 += std::abs(fa - fb);
        });
        c.worst_total = std::max(c.worst_total, std::abs(total_a - total_b));
        c.worst_l1 = std::max(c.worst_l1, l1);
    }
    return c;
}

}  // namespace hemirad::test
