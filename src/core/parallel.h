// The host stages' threads: loops over independent items spread over every host core (oneTBB),
// with results that do not depend on how many threads ran them or in what order. A body writes
// only what belongs to its own items; anything summed across items is summed afterwards in item
// order (or kept in exact integers), never in the order threads finish.
#pragma once

#include <cstddef>
#include <memory>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

namespace hemirad::parallel {

// body(begin, end) for consecutive ranges covering [0, count), each at least `grain` items but
// the last, on the host's threads (inline when one is allowed or count <= grain).
template <typename Body>
void for_ranges(std::size_t count, std::size_t grain, const Body& body) {
    if (count == 0) return;
    if (count <= grain) {
        body(std::size_t{0}, count);
        return;
    }
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, grain == 0 ? 1 : grain),
                      [&](const tbb::blocked_range<std::size_t>& r) { body(r.begin(), r.end()); });
}

// body(i) for every i in [0, count).
template <typename Body>
void for_each(std::size_t count, std::size_t grain, const Body& body) {
    for_ranges(count, grain, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) body(i);
    });
}

// Sorts [begin, end) by operator< on the host's threads. Only for values whose order is total
// and whose equal values are identical (keys, not records): which of two equal values comes first
// may depend on the threads.
template <typename Iterator>
void sort(Iterator begin, Iterator end) {
    tbb::parallel_sort(begin, end);
}

// The threads the host stages may use now (all cores unless a ThreadLimit holds).
int threads();

// While it lives, the host stages use at most `threads` threads (0: every core). The last one
// made wins; they nest as a stack. For `--threads` and the tests that vary the count.
class ThreadLimit {
public:
    explicit ThreadLimit(int threads);
    ~ThreadLimit();
    ThreadLimit(const ThreadLimit&) = delete;
    ThreadLimit& operator=(const ThreadLimit&) = delete;

private:
    struct State;
    std::unique_ptr<State> state_;
};

}  // namespace hemirad::parallel
