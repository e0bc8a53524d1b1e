// The command line: parses, runs, and is the one place that maps errors to exit codes.
#pragma once

#include <ostream>

namespace hemirad::cli {

// `hemirad devices`: one line per engine, or (json) a JSON array.
void list_devices(std::ostream& out, bool json);

// Returns the process exit code: 0 done, 2 bad input or usage, 1 internal or device failure.
int run(int argc, char** argv);

}  // namespace hemirad::cli
