// The CLI's progress line (see progress_line.h).
#include "cli/progress_line.h"

#include <cstdio>
#include <iostream>

#include <fmt/core.h>

#include "bake/budget.h"
#include "core/error.h"

namespace hemirad::cli {

ProgressLine::~ProgressLine() {
    if (on_ && tty_ && printed_) {
        std::fprintf(stderr, "\r\033[K");
        std::fflush(stderr);
    }
}

void ProgressLine::note(const std::string& line) {
    if (quiet_) return;
    finish();
    flush_held();
    std::cerr << "hemirad: " << printable(line) << "\n";
}

void ProgressLine::warning(const std::string& text, bool always) {
    if (quiet_ && !always) return;
    finish();
    flush_held();
    std::cerr << "hemirad: warning: " << printable(text) << "\n";
}

// A stage's line starts: its first status is shown at once.
void ProgressLine::begin_stage(const std::string& stage) {
    (void)stage;
    finish();
    start_ = Clock::now();
    last_ = -1e9;
    moved_ = false;
}

std::string ProgressLine::format(const Status& s) {
    std::string line = s.stage;
    if (s.fraction >= 0.0) line += fmt::format(" {:3.0f}%", 100.0 * s.fraction);
    if (!s.detail.empty()) line += "  " + s.detail;
    line += fmt::format("  {:.1f} s  left {}", s.elapsed, s.left < 0.0 ? std::string("?") : "~" + bake::format_duration(s.left));
    return line;
}

void ProgressLine::status(const Status& s) {
    // The stage's first progress is shown at once too (a log's first batch says the pace).
    const bool first = !moved_ && s.fraction > 0.0;
    if (s.fraction > 0.0) moved_ = true;
    if (!due(s.last || first)) return;
    const std::string line = format(s);
    if (!tty_ && (s.stage == "load" || s.stage == "mesh")) {
        held_.push_back(line);
        return;
    }
    flush_held();
    print(line);
}

void ProgressLine::finish() {
    if (on_ && tty_ && printed_) std::fprintf(stderr, "\n");
    printed_ = false;
}

bool ProgressLine::due(bool last) {
    if (!on_) return false;
    const double elapsed = seconds_since(start_);
    if (elapsed - last_ < (tty_ ? 0.2 : kLogSeconds) && !last) return false;
    last_ = elapsed;
    return true;
}

void ProgressLine::print(const std::string& line) {
    std::fprintf(stderr, tty_ ? "\r\033[K%s" : "hemirad: %s\n", line.c_str());
    std::fflush(stderr);
    printed_ = true;
}

void ProgressLine::flush_held() {
    for (const std::string& line : held_) {
        std::fprintf(stderr, "hemirad: %s\n", line.c_str());
    }
    if (!held_.empty()) std::fflush(stderr);
    held_.clear();
}

}  // namespace hemirad::cli
