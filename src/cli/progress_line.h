// The CLI's progress line (bake::Progress): on a terminal one line redrawn in place five times a
// second, in a log a line every few seconds; notes and warnings as "hemirad: …" lines on stderr.
// The line is the bake's, through every stage: "solve 37%  pass 1200 of ~3300, error 2.1e-03
// 12.3 s  left ~2 min" (the time left is the whole bake's, bake/stage_progress.h).
#pragma once

#include <string>
#include <vector>

#include "bake/progress.h"
#include "core/timing.h"

namespace hemirad::cli {

class ProgressLine final : public bake::Progress {
public:
    // On a terminal (tty), one line redrawn in place five times a second; in a log, a line every
    // kLogSeconds (and each stage's first and last).
    static constexpr double kLogSeconds = 5.0;
    // `on`: progress shown; `tty`: drawn in place; `quiet`: no notes or warnings but those that
    // are always shown.
    ProgressLine(bool on, bool tty, bool quiet) : on_(on), tty_(tty), quiet_(quiet) {}
    // A line still drawn in place is a bake that failed: it is erased, so that the error is the
    // one line left (bad input is one line on stderr).
    ~ProgressLine() override;
    ProgressLine(const ProgressLine&) = delete;
    ProgressLine& operator=(const ProgressLine&) = delete;

    void note(const std::string& line) override;
    void warning(const std::string& text, bool always) override;
    void begin_stage(const std::string& stage) override;
    void end_stage() override { finish(); }
    void status(const Status& s) override;
    void finish();

    // The line for `s`, as drawn.
    static std::string format(const Status& s);

private:
    bool due(bool last);
    void print(const std::string& line);
    void flush_held();
    bool on_, tty_, quiet_;
    Clock::time_point start_ = Clock::now();
    double last_ = -1e9;
    bool printed_ = false;
    bool moved_ = false;  // the stage has shown progress
    // In a log, the lines of loading and meshing wait until the bake is past its input's checks
    // (the next stage, or a note or warning): a bad file is then one line.
    std::vector<std::string> held_;
};

}  // namespace hemirad::cli
