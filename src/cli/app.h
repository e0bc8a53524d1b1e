// The command line: parses, runs, and is the one place that maps errors to exit codes.
#pragma once

namespace hemirad::cli {

// Returns the process exit code: 0 done, 2 bad input or usage, 1 internal or device failure.
int run(int argc, char** argv);

}  // namespace hemirad::cli
