// The CLI's progress line (bake::Progress): on a terminal one line redrawn in place five times a
// second, in a log a line every few seconds; notes and warnings as "hemirad: …" lines on stderr.
#pragma once

#include <cmath>
#include <cstdio>
#include <string>

#include <fmt/core.h>

#include "bake/progress.h"
#include "core/timing.h"
#include "solve/progressive.h"

namespace hemirad::cli {

class ProgressLine final : public bake::Progress {
public:
    // On a terminal (tty), one line redrawn in place five times a second; in a log, a line every
    // kLogSeconds.
    static constexpr double kLogSeconds = 5.0;
    // `on`: progress shown; `tty`: drawn in place; `quiet`: no notes or warnings but those that
    // are always shown.
    ProgressLine(bool on, bool tty, bool quiet) : on_(on), tty_(tty), quiet_(quiet), start_(Clock::now()) {}
    void note(const std::string& line) override;
    void warning(const std::string& text, bool always) override;
    void begin_stage() override;
    void end_stage() override { finish(); }
    void passes(const solve::Progressive& solver, double threshold) override {
        if (!due(solver.done())) return;
        const double elapsed = seconds_since(start_);
        const double err = solver.error();
        if (first_error_ <= 0.0 && std::isfinite(err) && err > 0.0) {
            first_error_ = err;
            first_time_ = elapsed;
        }
        // The error falls roughly exponentially with time: extrapolate log(error) linearly.
        std::string eta = "?";
        if (first_error_ > 0.0 && err > threshold && err < first_error_ && elapsed > first_time_) {
            const double rate = std::log(first_error_ / err) / (elapsed - first_time_);
            eta = fmt::format("~{:.0f} s", std::log(err / threshold) / rate);
        } else if (solver.done()) {
            eta = "0 s";
        }
        print(fmt::format("pass {}  unshot {:.2e}  error {:.2e}  {:.1f} s  left {}", solver.passes(),
                          solver.unshot_fraction(), err, elapsed, eta));
    }
    void lights(std::size_t done, std::size_t total) override {
        if (!due(done >= total)) return;
        print(fmt::format("lights' hemicubes {} / {}  {:.1f} s", done, total, seconds_since(start_)));
    }
    void rows(long done, long total) override {
        if (!due(done >= total)) return;
        print(fmt::format("form-factor rows {} / {}  {:.1f} s", done, total, seconds_since(start_)));
    }
    void gathering(long points, long total) override {
        if (!due(points >= total)) return;
        print(fmt::format("final gather {} / {} vertices  {:.1f} s", points, total, seconds_since(start_)));
    }
    void refining(int level, long shots, long total) override {
        if (!due(shots >= total)) return;
        print(fmt::format("refinement level {}: re-gather {} / {} shots  {:.1f} s", level, shots, total,
                          seconds_since(start_)));
    }
    void finish() {
        if (on_ && tty_ && printed_) std::fprintf(stderr, "\n");
        printed_ = false;
    }

private:
    bool due(bool last) {
        if (!on_) return false;
        const double elapsed = seconds_since(start_);
        if (elapsed - last_ < (tty_ ? 0.2 : kLogSeconds) && !last) return false;
        last_ = elapsed;
        return true;
    }
    void print(const std::string& line) {
        std::fprintf(stderr, tty_ ? "\r\033[K%s" : "hemirad: %s\n", line.c_str());
        std::fflush(stderr);
        printed_ = true;
    }
    bool on_, tty_, quiet_;
    Clock::time_point start_;
    double last_ = -1e9, first_error_ = 0.0, first_time_ = 0.0;
    bool printed_ = false;
};


}  // namespace hemirad::cli
