// Procedural scenes for scaling benchmarks: a closed, lit room filled with a grid of objects whose
// tessellation is chosen to give a requested triangle count, from about 100 to tens of millions.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>

#include "scene/scene.h"

namespace hemirad::gen {

using scene::Scene;

// Requests above this are refused: at ~160 bytes a Triangle, 50M is already 8 GB before meshing.
inline constexpr std::size_t kMaxProceduralTriangles = 50'000'000;

// A closed room (10 × 4 × 10 m, y up, walls facing in) lit by a ceiling panel facing down, with a
// G×G grid of closed, outward-facing boxes and ellipsoids standing on the floor: about `triangles`
// triangles in all (within ~1% from 1k up, a few % below that; never fewer than 50). Objects
// scale with the grid cell, so the floor area they cover stays the same whatever the count: only
// the tessellation changes the cost. Deterministic: same arguments, same bytes; `seed` moves,
// colours and sizes the objects but does not change the triangle count.
// Node 0 is the room (one primitive per wall), node 1 the light, then one node per object,
// "object_<row>_<column>", each one primitive with its triangles contiguous. Scene::path is
// "procedural:<count>" written as 1M, 100k or plain digits, for messages and reports.
Scene procedural_scene(std::size_t triangles, std::uint64_t seed = 1);

// Where procedural_with_clutter puts the extra objects: 20 m below the room's floor (behind every
// floor shooter) or 20 m along +x, beyond its wall (in front of them, hidden by the wall).
enum class Clutter { below, beyond };

// procedural_scene(room) with the objects of procedural_scene(clutter) (not its room or light)
// moved out of the room as `where` says, in nodes and primitives of their own: what hidden
// geometry costs a shot (bench/culling.cpp) and what occlusion culling may hide (the tests).
Scene procedural_with_clutter(std::size_t room, std::size_t clutter, Clutter where);

// "procedural:<count>" with count a whole number, optionally with a k (×1000) or M (×10⁶) suffix
// and then a decimal fraction ("procedural:100", "procedural:100k", "procedural:2.5M"). Returns
// nullopt when `spec` does not start with "procedural:" (it names a file); throws InputError with
// one line when the count is malformed, zero or above kMaxProceduralTriangles.
std::optional<std::size_t> parse_procedural_spec(const std::string& spec);

// The count of any "<prefix><count>" spec, read as parse_procedural_spec reads "procedural:"'s
// (the same syntax, limit and messages), so every generated scene kind takes the same counts.
std::optional<std::size_t> parse_count_spec(const std::string& spec, const std::string& prefix);

// "1M", "250k" or digits: how a requested count reads back in scene paths and reports.
std::string count_label(std::size_t n);

}  // namespace hemirad::gen
