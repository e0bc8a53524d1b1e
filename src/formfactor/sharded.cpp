// One engine over several (see sharded.h).
#include "formfactor/sharded.h"

#include <algorithm>
#include <chrono>
#include <deque>
#include <exception>
#include <thread>
#include <utility>

#include "core/error.h"

namespace hemirad::formfactor {

ShardedEngine::ShardedEngine(std::vector<Member> members, std::function<std::string(const std::exception&)> failure,
                             std::shared_ptr<ShardStats> stats)
    : failure_(std::move(failure)), stats_(std::move(stats)) {
    if (members.empty()) throw InternalError("sharded engine: no members");
    for (Member& m : members) {
        if (!m.engine) throw InternalError("sharded engine: a member without an engine");
        slots_.push_back({std::move(m), true});
    }
    if (stats_) {
        std::lock_guard lock(stats_->mutex);
        for (const Slot& s : slots_) {
            const auto known = std::find_if(stats_->members.begin(), stats_->members.end(),
                                            [&](const ShardStats::Member& m) { return m.id == s.member.id; });
            if (known == stats_->members.end()) stats_->members.push_back({s.member.id, 0, 0, 0.0, {}});
        }
    }
}

ShardedEngine::~ShardedEngine() = default;

std::string ShardedEngine::name() const {
    std::string out;
    for (const Slot& s : slots_) out += (out.empty() ? "" : "+") + s.member.engine->name();
    return out;
}

std::size_t ShardedEngine::live() const {
    return static_cast<std::size_t>(std::count_if(slots_.begin(), slots_.end(), [](const Slot& s) { return s.live; }));
}

void ShardedEngine::shoot(const ShotRequest& request, ShotResult& out) {
    shoot_batch({request}, one_);
    out = std::move(one_.front());
}

void ShardedEngine::record(std::size_t slot, long shots, double seconds, const std::string& dropped) {
    if (!stats_) return;
    std::lock_guard lock(stats_->mutex);
    for (ShardStats::Member& m : stats_->members)
        if (m.id == slots_[slot].member.id) {
            m.shots += shots;
            m.chunks += shots > 0 ? 1 : 0;
            m.seconds += seconds;
            if (!dropped.empty() && m.dropped.empty()) m.dropped = dropped;
        }
}

void ShardedEngine::shoot_batch(const std::vector<ShotRequest>& shots, std::vector<ShotResult>& out) {
    out.resize(shots.size());
    if (shots.empty()) return;
    const std::size_t n = shots.size();
    // Guided self-scheduling: each take is a share of what is left, so that launches start large
    // (a GPU wants many shots at once) and end small (the members finish together).
    std::size_t next = 0;                                    // shots [next, n) not yet taken
    std::deque<std::pair<std::size_t, std::size_t>> queue;   // [first, end) given back by a member that dropped out
    const auto take = [&](std::size_t live_members) -> std::pair<std::size_t, std::size_t> {
        if (!queue.empty()) {
            const auto range = queue.front();
            queue.pop_front();
            return range;
        }
        const std::size_t left = n - next;
        const std::size_t size =
            live_members <= 1 ? left : std::max<std::size_t>(1, (left + kShareOfRest * live_members - 1) / (kShareOfRest * live_members));
        const std::pair<std::size_t, std::size_t> range{next, next + size};
        next += size;
        return range;
    };
    std::mutex mutex;  // guards queue, fatal and the slots' `live`
    std::exception_ptr fatal;
    const auto work = [&](std::size_t slot) {
        std::vector<ShotRequest> part;
        std::vector<ShotResult> rows;
        for (;;) {
            std::pair<std::size_t, std::size_t> range;
            {
                std::lock_guard lock(mutex);
                if (fatal || (queue.empty() && next == n) || !slots_[slot].live) return;
                range = take(live());
            }
            try {
                part.assign(shots.begin() + static_cast<std::ptrdiff_t>(range.first),
                            shots.begin() + static_cast<std::ptrdiff_t>(range.second));
                const auto t0 = std::chrono::steady_clock::now();
                slots_[slot].member.engine->shoot_batch(part, rows);
                if (rows.size() != part.size()) throw InternalError("sharded engine: a member returned the wrong number of rows");
                for (std::size_t i = 0; i < rows.size(); ++i) out[range.first + i] = std::move(rows[i]);
                record(slot, static_cast<long>(part.size()),
                       std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), {});
            } catch (const std::exception& e) {
                const std::string why = failure_ ? failure_(e) : std::string();
                std::lock_guard lock(mutex);
                const bool others = std::any_of(slots_.begin(), slots_.end(), [&](const Slot& s) {
                    return s.live && &s != &slots_[slot];
                });
                if (!why.empty() && slots_[slot].member.may_drop && others) {
                    slots_[slot].live = false;  // its chunk goes to the others, with the same rows
                    queue.push_front(range);
                    record(slot, 0, 0.0, why);
                    return;
                }
                if (!fatal) fatal = std::current_exception();
                return;
            } catch (...) {
                std::lock_guard lock(mutex);
                if (!fatal) fatal = std::current_exception();
                return;
            }
        }
    };
    // Rounds: a member that drops out after the others have finished leaves its chunk for the next.
    while ((!queue.empty() || next < n) && !fatal) {
        std::vector<std::size_t> live_slots;
        for (std::size_t s = 0; s < slots_.size(); ++s)
            if (slots_[s].live) live_slots.push_back(s);
        if (live_slots.empty()) throw InternalError("sharded engine: no member left");
        std::vector<std::thread> threads;
        for (std::size_t i = 1; i < live_slots.size(); ++i) threads.emplace_back(work, live_slots[i]);
        work(live_slots.front());
        for (std::thread& t : threads) t.join();
    }
    if (fatal) std::rethrow_exception(fatal);
}

std::size_t ShardedEngine::preferred_batch() const {
    std::size_t batch = 0;
    for (const Slot& slot : slots_)
        if (slot.live) batch += slot.member.engine->preferred_batch();
    return std::max<std::size_t>(kDefaultBatch, batch);
}

}  // namespace hemirad::formfactor
