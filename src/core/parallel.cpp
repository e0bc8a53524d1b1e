#include "core/parallel.h"

#include <algorithm>

#include <tbb/global_control.h>

namespace hemirad::parallel {

struct ThreadLimit::State {
    std::unique_ptr<tbb::global_control> control;
};

ThreadLimit::ThreadLimit(int threads) : state_(std::make_unique<State>()) {
    if (threads > 0)
        state_->control = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                                static_cast<std::size_t>(threads));
}

ThreadLimit::~ThreadLimit() = default;

int threads() {
    return static_cast<int>(
        std::max<std::size_t>(1, tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism)));
}

}  // namespace hemirad::parallel
