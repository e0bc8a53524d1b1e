// `hemirad bench` (see bench.h): runs a benchmark and writes its JSON document atomically.
#include "bench/command.h"

#include <fmt/core.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <system_error>

#include "bench/effects.h"
#include "bench/estimate.h"
#include "bench/image.h"
#include "core/error.h"

namespace hemirad::bench {
namespace fs = std::filesystem;

namespace {

// The JSON goes to a temporary file beside the target, renamed over it when complete: a failed
// or interrupted run never leaves a half-written file, nor destroys an earlier one.
class JsonFile {
public:
    explicit JsonFile(const std::string& target) : target_(target) {
        if (target_.empty()) return;
        temp_ = target_;
        temp_ += fmt::format(".tmp-{}", static_cast<long>(getpid()));
        std::ofstream probe(temp_);  // fail before hours of benchmarking, not after
        if (!probe) throw InputError(fmt::format("{}: cannot write the results (does its directory exist?)", target));
    }
    JsonFile(const JsonFile&) = delete;
    JsonFile& operator=(const JsonFile&) = delete;
    ~JsonFile() {
        std::error_code ec;  // destructors never throw
        if (!temp_.empty()) fs::remove(temp_, ec);
    }
    void commit(const nlohmann::ordered_json& doc) {
        if (target_.empty()) return;
        {
            std::ofstream out(temp_);
            out << doc.dump(2) << "\n";
            if (!out.good()) throw InputError(fmt::format("{}: cannot write the results", target_.string()));
        }
        std::error_code ec;
        fs::rename(temp_, target_, ec);
        if (ec) throw InputError(fmt::format("{}: cannot write the results: {}", target_.string(), ec.message()));
        temp_.clear();
    }

private:
    fs::path target_, temp_;
};

}  // namespace

void run_bench(const BenchCommand& command, std::ostream& log) {
    JsonFile json(command.json);
    if (command.accuracy + command.effects + command.scaling + command.estimate > 1)
        throw InputError("bench: --accuracy, --effects, --estimate and --scaling are separate runs");
    if (command.accuracy && !command.throughput.scenes.empty())
        throw InputError("bench --accuracy: takes no scenes (it builds its own)");
    if (command.effects && !command.throughput.scenes.empty())
        throw InputError("bench --effects: takes no scenes (it bakes the bundled ones)");
    if (command.quick && !command.accuracy && !command.effects && !command.estimate)
        throw InputError("bench: --quick goes with --accuracy, --effects or --estimate");
    nlohmann::ordered_json doc;
    if (command.accuracy) {
        ImageAccuracyOptions image;
        image.device = command.device;
        image.quick = command.quick;
        // Read before minutes of work: a run outside the repository root fails at once.
        const ImageReference reference = load_image_reference(image.reference_dir);
        doc = bench::run_accuracy({command.device, command.quick}, log);
        doc["accuracy"]["cornell"] = run_image_accuracy(image, reference, log);
    } else if (command.estimate) {
        EstimateBenchOptions options;
        options.device = command.device;
        options.quick = command.quick;
        options.scenes = command.throughput.scenes;
        doc = run_estimate_bench(options, log);
    } else if (command.scaling) {
        doc = run_scaling_bench(command.scaling_options, log);
    } else if (command.effects) {
        EffectsBenchOptions options;
        options.device = command.device;
        options.quick = command.quick;
        doc = run_effects_bench(options, log);
    } else {
        doc = bench::run_throughput(command.throughput, log);
    }
    json.commit(doc);
    if (!command.json.empty()) log << fmt::format("\nwrote {}\n", command.json);
}

}  // namespace hemirad::bench
