// The effects planner: a production baker simulates only what a scene calls for. plan_effects
// inspects a loaded scene and decides, effect by effect, whether it is needed, with a
// one-sentence reason naming the evidence; the user can force each effect on or off
// (`--effects occlusion=off,colour=on`).
#pragma once

#include <array>
#include <string>
#include <vector>

#include "scene/scene.h"

namespace hemirad::scene {

enum class Force { automatic, on, off };

// The effects `--effects` names, in the order --help and messages list them: a new effect is
// added here and to the slots of parse_effect_overrides (a static_assert there counts them).
inline constexpr std::array<const char*, 8> kEffectNames = {"occlusion",  "colour",      "interreflection", "two_sided",
                                                            "refinement", "convergence", "see_through",     "outlines"};

// kEffectNames as a list for people: "occlusion, colour, … see_through or outlines" (`last`:
// the word before the last name).
std::string effect_names(const char* last = "or");

struct EffectOverrides {
    Force occlusion = Force::automatic;
    Force colour = Force::automatic;
    Force interreflection = Force::automatic;
    Force two_sided = Force::automatic;
    Force refinement = Force::automatic;
    Force convergence = Force::automatic;
    Force see_through = Force::automatic;
    Force outlines = Force::automatic;
};

// Parses a comma-separated list of name=value items, e.g. "occlusion=off,colour=on,refinement=auto"
// (names: kEffectNames; values: on, off, auto). Spaces around items, names and values are ignored; an empty or all-blank
// spec leaves every effect automatic. Throws std::invalid_argument naming the bad item (an
// unknown name or value, an item without '=', an empty item, a name given twice).
EffectOverrides parse_effect_overrides(const std::string& spec);

struct EffectDecision {
    bool on = true;
    bool forced = false;  // set from the command line rather than by the scene analysis
    std::string why;      // one sentence naming the evidence
};

struct EffectsPlan {
    EffectDecision occlusion;        // visibility between surfaces (a hemicube or rays) is needed
    EffectDecision colour;           // three channels (off: reflectances and emissions are grey)
    EffectDecision interreflection;  // light bounces (off: every reflectance is 0)
    EffectDecision two_sided;        // doubleSided materials make back-face patches
    EffectDecision refinement;       // elements are split where the radiosity contrast is high
    EffectDecision convergence;      // stop once the unshot light can no longer show
    // Alpha-blended and transmissive surfaces (fake light shafts, glass) are seen through: left
    // out, so they neither block, emit nor receive (off: baked as opaque surfaces).
    EffectDecision see_through;
    // Inverted-hull toon outlines (scene/outlines.h), which every viewer culls, are left out like
    // see-through surfaces (off: kept, their backs blocking and absorbing the light).
    EffectDecision outlines;
    // The hulls' triangles, as indices into the scene once apply_see_through has run; left out
    // by apply_outlines where outlines is on.
    std::vector<std::size_t> outline_triangles;
};

// Decides every effect for `scene` (automatic ones from the scene, forced ones from
// `overrides`). Occlusion is judged on the surfaces as they will be meshed, that is after the
// two_sided decision: forcing two_sided on makes occlusion necessary (back faces), forcing it
// off lets the geometry decide.
//
// Occlusion is off only when no surface can hide another: every vertex of the scene lies on
// or in front of every triangle's plane (tolerance 1e-9 × the scene's diagonal), i.e. the
// surfaces bound a convex region seen from inside. The check groups triangles by plane and
// stops at the first vertex behind one; beyond 2e8 plane × vertex tests it assumes occlusion.
EffectsPlan plan_effects(const Scene& scene, const EffectOverrides& overrides);

// Applies the two_sided decision to the scene's materials (call it on the copy that will be
// meshed): two_sided forced on → every material double-sided; two_sided off (forced or
// automatic) → every material one-sided; otherwise unchanged.
void apply_two_sided(Scene& scene, const EffectsPlan& plan, const EffectOverrides& overrides);

// Applies the see_through decision (on the copy that will be meshed): on → the triangles of
// see-through materials are removed (their nodes stay, with no surface); off → kept as opaque.
void apply_see_through(Scene& scene, const EffectsPlan& plan);

// Applies the outlines decision (after apply_see_through, on the same copy): on → the hulls'
// triangles are removed (their nodes stay, with no surface); off → kept.
void apply_outlines(Scene& scene, const EffectsPlan& plan);

// Applies the colour decision: off (planned for a grey scene, or forced) replaces every
// reflectance and emission by its luminance, so one channel holds the whole solution; a grey
// scene is unchanged.
void apply_colour(Scene& scene, const EffectsPlan& plan);

// "on", "off" or "auto".
const char* to_string(Force force);

}  // namespace hemirad::scene
