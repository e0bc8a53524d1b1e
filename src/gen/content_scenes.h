// Content-like procedural scenes for the scale benchmarks: a city, a furnished room and a planted
// courtyard, built the way real exports are (small coplanar facade quads, bevelled boxes and
// finely tessellated cylinders, double-sided foliage cards) and sized to a requested triangle count.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>

#include "scene/scene.h"

namespace hemirad::gen {

using scene::Scene;

enum class ContentKind {
    // Open: n × n blocks of buildings (extruded footprints with inset windows, ledges, parapets and
    // roof units) on curbed pads between streets, under an emissive overcast "sky lid" facing down
    // that covers the city and its margin; the sides are open, so light escapes there.
    kCity,
    // Closed: a hall of n × n cells, each a dining set, a lounge (sofa, armchair, coffee table) or
    // shelving with books, built of chamfered boxes and cylinders, and a ceiling lamp per cell.
    kFurniture,
    // Closed: a walled courtyard of n × n cells, each a tree (tapered trunk in a planter, canopy of
    // leaf cards), bushes and grass tufts of double-sided cards, lit by ceiling skylight panels.
    kFoliage,
};

// "city", "furniture" or "foliage": the spec prefix without its colon.
const char* content_kind_name(ContentKind kind);

// Whether every direction from every surface hits another surface (no light can escape).
bool content_kind_closed(ContentKind kind);

// About `triangles` triangles (within ~3% from 10k up; never fewer than the smallest layout's,
// a few thousand). Layout and detail grow together: the number of blocks/cells with about the
// fourth root of the count, each object's tessellation level with the rest. Deterministic: same
// arguments, same triangles in the same order; `seed` moves, sizes and colours the objects (the
// count is refitted for each seed, so it moves a little with it). One node per object, named
// "<kind>_<index>"; node 0 is the shell (ground or room), node 1 the emitters. Scene::path is
// "<kind>:<count>" as count_label writes it; one camera.
Scene content_scene(ContentKind kind, std::size_t triangles, std::uint64_t seed = 1);

struct ContentSpec {
    ContentKind kind;
    std::size_t triangles;
};

// "city:<count>", "furniture:<count>" or "foliage:<count>" with the count read as
// parse_procedural_spec reads it (100k, 2.5M). nullopt for anything else; InputError (one line)
// for a malformed count.
std::optional<ContentSpec> parse_content_spec(const std::string& spec);

// A scene generated from a spec: procedural:<count> or any content kind. nullopt when `spec` is
// none of them (it names a file). `closed` is set to whether the scene is closed.
std::optional<Scene> generated_scene(const std::string& spec, bool* closed = nullptr, std::uint64_t seed = 1);

}  // namespace hemirad::gen
