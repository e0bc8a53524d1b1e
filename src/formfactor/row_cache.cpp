// The form-factor row memo (see row_cache.h).
#include "formfactor/row_cache.h"

#include <utility>

namespace hemirad::formfactor {

std::size_t RowCacheEngine::KeyHash::operator()(const Key& k) const {
    std::uint64_t h = (std::uint64_t(k.kind) << 32 | k.patch) * 0x9E3779B97F4A7C15ull;
    h ^= (k.shot + 0x632BE59BD9B4E019ull) * 0xC2B2AE3D27D4EB4Full;
    return static_cast<std::size_t>(h ^ (h >> 31));
}

RowCacheEngine::RowCacheEngine(std::unique_ptr<Engine> inner, double budget_bytes) : inner_(std::move(inner)) {
    stats_.budget_bytes = budget_bytes;
}

double RowCacheEngine::row_bytes(const ShotResult& row) {
    constexpr double kPerRow = 128.0;  // the map's node and the use list's
    return kPerRow + double(row.element.capacity()) * sizeof(std::uint32_t) + double(row.F.capacity()) * sizeof(double);
}

void RowCacheEngine::shoot(const ShotRequest& request, ShotResult& out) {
    std::vector<ShotResult> one;
    shoot_batch({request}, one);
    out = std::move(one.front());
}

void RowCacheEngine::shoot_batch(const std::vector<ShotRequest>& shots, std::vector<ShotResult>& out) {
    out.resize(shots.size());
    inner_index_.assign(shots.size(), -1);
    misses_.clear();
    for (std::size_t i = 0; i < shots.size(); ++i) {
        ++stats_.requests;
        const auto it = rows_.find(key_of(shots[i]));
        if (it == rows_.end()) {
            inner_index_[i] = static_cast<long>(misses_.size());
            misses_.push_back(shots[i]);
            continue;
        }
        ++stats_.hits;
        use_.splice(use_.begin(), use_, it->second.use);
        out[i] = it->second.result;
    }
    if (misses_.empty()) return;
    stats_.shot += static_cast<long>(misses_.size());
    inner_->shoot_batch(misses_, shot_);
    for (std::size_t i = 0; i < shots.size(); ++i) {
        if (inner_index_[i] < 0) continue;
        const ShotResult& row = shot_[std::size_t(inner_index_[i])];
        out[i] = row;
        if (shots[i].shooter.kind != Shooter::Kind::patch) continue;  // a light shoots once a level
        const std::uint32_t patch = shots[i].shooter.patch;
        if (patch >= seen_.size()) seen_.resize(std::size_t(patch) + 1, false);
        if (seen_[patch]) keep(key_of(shots[i]), row);
        seen_[patch] = true;
    }
}

void RowCacheEngine::keep(const Key& key, const ShotResult& row) {
    if (rows_.count(key) > 0) return;  // the same request twice in one batch
    ShotResult copy = row;
    copy.element.shrink_to_fit();
    copy.F.shrink_to_fit();
    const double bytes = row_bytes(copy);
    if (bytes > stats_.budget_bytes) return;
    while (bytes_ + bytes > stats_.budget_bytes && !use_.empty()) {
        const auto last = rows_.find(use_.back());
        bytes_ -= row_bytes(last->second.result);
        rows_.erase(last);
        use_.pop_back();
        ++stats_.dropped;
    }
    use_.push_front(key);
    rows_.emplace(key, Row{std::move(copy), use_.begin()});
    bytes_ += bytes;
    ++stats_.kept;
    if (bytes_ > stats_.peak_bytes) stats_.peak_bytes = bytes_;
}

const std::vector<std::int32_t>* RowCacheEngine::last_ids(std::size_t i) const {
    if (i >= inner_index_.size() || inner_index_[i] < 0) return nullptr;
    return inner_->last_ids(std::size_t(inner_index_[i]));
}

}  // namespace hemirad::formfactor
