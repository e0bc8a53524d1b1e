// `hemirad bench --accuracy`, the image part: the bundled Cornell box baked the way a user bakes it
// (`hemirad bake`, the planner's engines and solvers) at the presets and along --gather,
// --gather-passes, --hemicube and --element-size sweeps from the default, each compared pixel by pixel and face by face with a converged reference
// of an independent path tracer (bench/pathtrace.cpp, rendered offline by
// bench/make_references.sh into bench/reference/<scene>/ and committed).
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <ostream>
#include <string>
#include <vector>

namespace hemirad::bench {

// A path-traced reference: reference.exr (R, G, B radiosity; noise.Y, its luminance's standard error; face:
// the face all of a pixel's samples hit, −1 for none or several) and reference.json (faces with
// node, normal, offset, area, emitter and area-averaged radiosity).
struct ImageReference {
    int width = 0, height = 0;
    std::vector<float> rgb;        // width × height × 3
    std::vector<float> noise_y;    // the luminance's standard error, per pixel
    std::vector<int> face;         // per pixel, −1: an edge or nothing
    nlohmann::ordered_json json;   // reference.json
};

// Reads `dir`/reference.exr and `dir`/reference.json. Throws InputError naming the file when one
// is missing or not a reference.
ImageReference load_image_reference(const std::string& dir);

// The linear RGB of an EXR file (a bake's render.exr), as floats, row 0 at the top; its size in
// `width` and `height`. Throws InputError naming the file without R, G and B channels.
std::vector<float> read_rgb(const std::filesystem::path& file, int& width, int& height);

// Per-pixel error of a linear RGB image (same size, row 0 at the top) against the reference, over
// the reference's interior pixels (all samples on one face that does not emit): relative error of
// the luminance, (hemirad − reference) / reference. rms: the RMS relative error with the
// reference's own noise removed (sqrt(max(0, mean e² − mean σ²)), σ its relative standard error);
// raw_rms without that; noise_rms the reference's; worst_tile the largest |mean e| over 16 × 16
// tiles with at least a quarter of their pixels interior, and where it lies; worst_tile_light the
// largest |relative error of a tile's light| (its interior pixels' luminance summed, against the
// reference's), with that sum's relative standard error from the reference's noise. The first is
// ruled by a tile's darkest pixels and grows with the reference's noise there (the mean of
// (h − r)/r over noisy r is biased upward by about the relative variance: +1% and more on the
// short block's dark front); the second says how far off a region looks as a whole.
struct PixelErrors {
    double rms = 0.0, raw_rms = 0.0, noise_rms = 0.0, mean = 0.0;
    double worst_tile = 0.0;
    int worst_tile_x = 0, worst_tile_y = 0;  // pixel coordinates of its top-left corner
    double worst_tile_light = 0.0, worst_tile_light_noise = 0.0;
    int worst_tile_light_x = 0, worst_tile_light_y = 0;
    long pixels = 0;
};
PixelErrors compare_pixels(const std::vector<float>& rgb, int width, int height, const ImageReference& reference);

// Per face of the reference seen from the camera: the mean luminance over its interior pixels
// (as compare_pixels counts them) of the image and of the reference, and their relative
// difference. Faces with fewer than `min_pixels` interior pixels are left out. Returns
// [{face, node, normal, emitter, pixels, reference, hemirad, error}]. (The reference's area
// averages, reference.json's faces, count the parts no one sees too: the floor under a box, the
// ceiling behind the lamp, where a final gather gives a vertex its seen neighbours' light; the
// image is what a user compares.)
nlohmann::ordered_json compare_faces(const std::vector<float>& rgb, int width, int height,
                                     const ImageReference& reference, long min_pixels = 200);

struct ImageAccuracyOptions {
    std::string device = "auto";
    bool quick = false;  // draft and default only, no sweeps
    std::string reference_dir = "bench/reference/cornell_box";
    std::string scene = "scenes/cornell_box.gltf";
};

// Bakes the scene at each preset and sweep point, compares with `reference` (load_image_reference of
// options.reference_dir) and returns {scene, reference, runs: [{label,
// sweep, quality, options, gather_points, seconds, timings_s, elements, solver, pixels:
// PixelErrors, worst_block_face, worst_face, faces (compare_faces)}]}; prints a table to `log`.
nlohmann::ordered_json run_image_accuracy(const ImageAccuracyOptions& options, const ImageReference& reference,
                                          std::ostream& log);

}  // namespace hemirad::bench
