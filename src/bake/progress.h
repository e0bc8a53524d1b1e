// What a bake tells whoever runs it while it runs: lines of news, warnings, and how far each long
// stage is. The CLI draws a progress line (cli/progress_line.h); a library caller may ignore it all
// (the default: every method does nothing). Warnings also go into report.json whatever this does.
#pragma once

#include <cstddef>
#include <string>

namespace hemirad::solve {
class Progressive;
}

namespace hemirad::bake {

class Progress {
public:
    virtual ~Progress() = default;
    // A line of news ("form factors on …", the summary at the end); not under --quiet.
    virtual void note(const std::string& line) { (void)line; }
    // A warning. `always`: shown even under --quiet (the scene's own problems, a device that failed).
    virtual void warning(const std::string& text, bool always) {
        (void)text;
        (void)always;
    }
    // The punctual lights' hemicubes, `done` of `total`.
    virtual void lights(std::size_t done, std::size_t total) {
        (void)done;
        (void)total;
    }
    // The progressive solver after a pass; it stops below `threshold`.
    virtual void passes(const solve::Progressive& solver, double threshold) {
        (void)solver;
        (void)threshold;
    }
    // The matrix solver's form-factor rows.
    virtual void rows(long done, long total) {
        (void)done;
        (void)total;
    }
    // Adaptive refinement's re-gather at `level`.
    virtual void refining(int level, long shots, long total) {
        (void)level;
        (void)shots;
        (void)total;
    }
    // Adaptive refinement is over: the elements it left (the gather's and the output's work).
    virtual void refined(std::size_t elements) { (void)elements; }
    // The final gather's vertices.
    virtual void gathering(long points, long total) {
        (void)points;
        (void)total;
    }
    // A sparse gather's hemicubes (solve/sparse_gather.h): `points` of at most `budget`, one pass.
    virtual void gathering_sparse(long points, long budget) {
        (void)points;
        (void)budget;
    }
    // A stage begins (`stage`: load, mesh, solve, refine, gather, output): its clock starts; and
    // ends: its line is closed.
    virtual void begin_stage(const std::string& stage) { (void)stage; }
    virtual void end_stage() {}
    // The output stage's steps as they start: "weld", "render", "render.exr", "render.png",
    // "baked.gltf".
    virtual void writing(const std::string& what) { (void)what; }

    // What the progress line shows: the bake as a whole, from the time model (bake/eta.h) that
    // the calls above feed (bake::run wraps the caller's Progress in a StageProgress that makes
    // these from them).
    struct Status {
        std::string stage;     // load, mesh, lights, solve, refine, gather, output
        std::string detail;    // the stage's own count ("pass 1,200 of ~3,000, error 2.1e-03")
        double fraction = -1;  // of the stage, 0..1; < 0 unknown
        double elapsed = 0;    // seconds in the stage
        double left = -1;      // seconds left of the bake (this stage's rest and every later one); < 0 unknown
        bool last = false;     // the stage's final status (always shown)
    };
    virtual void status(const Status& s) { (void)s; }
};

}  // namespace hemirad::bake
