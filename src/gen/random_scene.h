// Random scenes shaped like real exports (Blender, Sketchfab): UV spheres, cylinders, tori, boxes
// and thin walls, double- and one-sided, emitting and reflecting, under nested rotated, scaled and
// mirrored nodes, with deliberately degenerate triangles, at scales from 1e-3 to 1e3. They are
// written as glTF, so a bake of one takes the path a real file takes (the loader, its node
// transforms and its doubleSided handling). The seeded random-scene test and the bake fuzzer
// share this generator: a seed or a fuzzer's bytes drive it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace hemirad::gen {

// The source of every random choice: the given bytes read in order (a fuzzer's input), then
// zeros once they run out, so any input, even an empty one, makes a scene. A seed is expanded
// into bytes first, so seeded scenes and fuzzed ones take the same path. Deterministic: the same
// bytes give the same choices on every machine (no floating point in the expansion).
class Choices {
public:
    // Past the end of `bytes`, further bytes come from a SplitMix64 stream seeded by a hash of
    // them (not zeros, which made chance(p) true for every p once a short input ran out).
    explicit Choices(std::vector<std::uint8_t> bytes);
    Choices(const std::uint8_t* data, std::size_t size) : Choices(std::vector<std::uint8_t>(data, data + size)) {}
    // kSeedBytes bytes of SplitMix64 from `seed`.
    static Choices from_seed(std::uint64_t seed);
    static constexpr std::size_t kSeedBytes = 8192;

    std::uint32_t below(std::uint32_t n);      // in [0, n); 0 when n <= 1
    int between(int lo, int hi);               // in [lo, hi]
    double unit();                             // in [0, 1], 16 bits
    double uniform(double lo, double hi);      // lo + (hi − lo) · unit()
    double log_uniform(double lo, double hi);  // lo · (hi / lo)^unit(); lo, hi > 0
    bool chance(double p);                     // unit() < p

    std::size_t consumed() const { return next_; }  // bytes read so far, the stream's included

private:
    std::uint8_t byte();
    std::vector<std::uint8_t> bytes_;
    std::uint64_t tail_seed_ = 0;  // a hash of bytes_
    std::size_t next_ = 0;
};

// Bounds on what one scene may hold, so a fuzzer's input cannot ask for a bake of hours.
struct RandomSceneLimits {
    int max_objects = 6;          // objects besides the optional floor or room
    int max_triangles = 600;      // all objects together, degenerate ones included (roughly)
};

// One mesh node of a random scene.
struct RandomObject {
    std::string node;           // the glTF node's name
    std::string shape;          // "sphere 12x6", "torus 8x4 r0.20", …
    std::size_t triangles = 0;  // the mesh's triangles, degenerate ones included
    // A closed surface facing out (sphere, box, torus, capped cylinder, or the room facing in)
    // with nothing added to it: its loaded triangles enclose a positive signed volume (a negative
    // one for the room), whatever the node's transform does.
    bool closed = false;
    bool inward = false;        // faces in: the room, or an object an exporter turned inside out
    bool mirrored = false;      // the node's world transform has a negative determinant
    bool emits = false;         // its material is emissive
};

// What write_random_scene wrote, for messages and for tests' expectations.
struct RandomSceneInfo {
    std::string summary;              // one line: every object's shape, material and transform chain
    std::vector<RandomObject> objects;  // per mesh node, in the order written
    std::size_t triangles = 0;        // triangles written, once per node that holds them
    std::size_t degenerate = 0;       // triangles of the meshes written deliberately degenerate or duplicated
    bool mirrored = false;            // some mesh node's world transform has a negative determinant
    bool double_sided = false;        // some material is doubleSided
};

// Builds a random scene from `choices` and writes it to `file` (.gltf, its buffer embedded as a
// data URI; the file is replaced). Its first object always uses an emissive material and has
// triangles with area, so the scene has an emitter. May add a floor or a closed room around the
// objects, a camera, per-vertex colours (COLOR_0), instanced meshes (one mesh under two nodes).
// Throws std::runtime_error when the file cannot be written.
RandomSceneInfo write_random_scene(Choices& choices, const std::filesystem::path& file,
                                   const RandomSceneLimits& limits = {});

}  // namespace hemirad::gen
