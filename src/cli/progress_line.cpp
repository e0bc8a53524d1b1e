// The CLI's progress line (see progress_line.h).
#include "cli/progress_line.h"

#include <iostream>

#include "core/error.h"

namespace hemirad::cli {

void ProgressLine::note(const std::string& line) {
    if (quiet_) return;
    finish();
    std::cerr << "hemirad: " << printable(line) << "\n";
}

void ProgressLine::warning(const std::string& text, bool always) {
    if (quiet_ && !always) return;
    finish();
    std::cerr << "hemirad: warning: " << printable(text) << "\n";
}

// A stage's clock starts, and its error's extrapolation with it.
void ProgressLine::begin_stage() {
    finish();
    start_ = Clock::now();
    last_ = -1e9;
    first_error_ = 0.0;
    first_time_ = 0.0;
}

}  // namespace hemirad::cli
