// The bake behind `hemirad bake`, as a library: plan → load → set up → mesh → solve (with the
// device fallback around it) → refine → gather → write outputs → write report; all or nothing.
// docs/architecture.md says which stage a change belongs to.
#pragma once

#include "bake/options.h"
#include "bake/progress.h"
#include "core/cancel.h"

namespace hemirad::bake {

// Thrown when a signal stops a bake (core/cancel.h); nothing has been written (or it was removed).
using Interrupted = cancel::Interrupted;

// Runs a bake, telling `progress` how it goes. Throws InputError (exit 2), Interrupted, or other
// exceptions (exit 1). On any throw, whatever this run wrote under the output directory has been
// removed.
void run(const Options& options, Progress& progress);
// … telling no one (warnings are still in report.json).
void run(const Options& options);

}  // namespace hemirad::bake
