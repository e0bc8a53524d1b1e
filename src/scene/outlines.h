// Inverted-hull outlines (toon shading) told apart from rooms, and the share of the sun's and
// sky's light that lands on the backs of one-sided surfaces.
//
// A toon outline is an inverted hull: a slightly larger copy of an object, its faces turned
// inwards, one-sided, so that every viewer culls it except for a thin rim at silhouettes.
// hemirad lets the back of a one-sided surface block and absorb light (DESIGN.md), which is
// right for a room of one-sided walls facing inwards but traps every bit of light meant for the
// object inside a hull. Both are closed-ish one-sided shells facing inwards; what tells them
// apart is what they enclose: a hull is a near-copy of the object inside it, a room holds
// furniture far smaller than itself (and, usually, the camera).
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "scene/scene.h"

namespace hemirad::scene {

// The rule's tolerances. A shell of one-sided triangles (connected through shared vertex
// positions, within one node) is an inverted hull when
//   - it faces inwards: at least kInwardShare of its area faces its own area centroid;
//   - it encloses other geometry (non-see-through triangles of other shells, wholly inside the
//     shell's bounding box) and no camera;
//   - it hugs it: on each of the six sides the gap between the shell's bounding box and the
//     enclosed geometry's is at most kHugFraction of the shell's diagonal, and at least
//     kHuggedVertices of the shell's (distinct) vertices lie within kHugFraction of the diagonal
//     of a vertex of the enclosed geometry.
// A name that says so ("outline", "ink", "hull", "inverted", on the node or the material) is
// supporting evidence only: it doubles kHugFraction, never makes a hull by itself.
inline constexpr double kInwardShare = 0.75;
inline constexpr double kHugFraction = 0.10;
inline constexpr double kHuggedVertices = 0.90;
// Then a one-material shell that is no hull by the rule above is one when more than kSiblingShare
// of its material's one-sided area lies in hulls, one of them at least as large as it, and
// kSiblingInwardShare or more of its own area faces its centroid (not an object's outward faces): an outline
// material's open pieces, or hulls around objects the rule did not confirm.
inline constexpr double kSiblingShare = 0.5, kSiblingInwardShare = 0.5;

struct OutlineHull {
    std::uint32_t node = 0;      // Scene::nodes index
    std::size_t triangles = 0;
    double gap = 0.0;            // the largest side gap to the enclosed geometry, in shell diagonals
    bool named = false;          // its node's or material's name says outline
    bool sibling = false;        // a hull by its material (kSiblingShare), not by what it encloses
};

struct OutlineSearch {
    std::vector<OutlineHull> hulls;
    std::vector<std::size_t> triangles;  // indices (ascending) of the hulls' triangles in the scene searched
    // Inward-facing one-sided shells that are not hulls (rooms, domes): their backs are meant to
    // be outside.
    std::size_t inward_shells = 0;
    std::string example_shell;           // one of them, by node name
};

// Finds the scene's inverted hulls (the synthetic sky and see-through materials never are one).
// Work grows as n log n in the triangles (a sort of their corners), plus each candidate's
// neighbourhood: a fraction of a second for a million triangles.
OutlineSearch find_outline_hulls(const Scene& scene);

// The share of the light that directional lights and the sky (--sky) send into the scene which
// first lands on the back of a one-sided surface: each light's view of the scene is rasterised
// (orthographic, nearest surface per cell; the sky as five directions), and cells whose nearest
// surface shows a one-sided back count, except backs of inward shells that are not hulls (a room
// built of one-sided walls facing inwards is meant to be seen from inside: the sun on its outer
// walls is right to stay out). Inward is judged per shell, per node and over the whole scene.
// Punctual point and spot lights and emissive surfaces are not counted.
inline constexpr double kBackLightWarning = 0.3;  // a share worth a warning
struct BackLight {
    // Of the light that lands on the scene. Below kBackLightWarning the backs that do not count
    // are not worked out (they could only lower it): it is then the share on all one-sided backs,
    // and triangles and example are left empty.
    double share = 0.0;
    std::size_t triangles = 0;  // distinct triangles whose backs take it
    std::string example;        // the node whose backs take most
};
std::optional<BackLight> back_light(const Scene& scene);


// A count with its thousands grouped: "52,824".
std::string grouped(std::size_t n);

// The warning for `scene` (as it will be meshed: after see_through and outlines), or nothing.
std::optional<std::string> back_light_warning(const Scene& scene);

}  // namespace hemirad::scene
