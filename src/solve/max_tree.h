// MaxTree: the index of the largest of n keys (ties to the lower index), kept up to date in
// O(log n) per changed key: the progressive solver's pick of the patch with the most unshot flux,
// at a cost that follows the patches a shot touched, not the patch count.
#pragma once

#include <cstdint>
#include <vector>

namespace hemirad::solve {

class MaxTree {
public:
    explicit MaxTree(std::vector<double> keys = {}) { reset(std::move(keys)); }

    void reset(std::vector<double> keys) {
        keys_ = std::move(keys);
        leaves_ = 1;
        while (leaves_ < keys_.size()) leaves_ *= 2;
        tree_.assign(2 * leaves_, kNone);
        for (std::size_t i = 0; i < keys_.size(); ++i) tree_[leaves_ + i] = static_cast<std::uint32_t>(i);
        for (std::size_t node = leaves_ - 1; node >= 1; --node) tree_[node] = winner(tree_[2 * node], tree_[2 * node + 1]);
    }

    std::size_t size() const { return keys_.size(); }
    double key(std::size_t i) const { return keys_[i]; }

    // Climbs only while the change can matter: where a node's winner stays what it was and is not
    // i, no key above it changed (most of a shot's touched patches stop a level or two up).
    void set(std::size_t i, double key) {
        keys_[i] = key;
        for (std::size_t node = (leaves_ + i) / 2; node >= 1; node /= 2) {
            const std::uint32_t was = tree_[node], now = winner(tree_[2 * node], tree_[2 * node + 1]);
            if (now == was && now != i) return;
            tree_[node] = now;
        }
    }

    // The index of the largest key, the lowest such index on ties; size() when empty.
    std::size_t top() const { return tree_.size() > 1 && tree_[1] != kNone ? tree_[1] : keys_.size(); }

private:
    static constexpr std::uint32_t kNone = UINT32_MAX;
    std::vector<double> keys_;
    std::vector<std::uint32_t> tree_;  // node 1 the root, node n's children 2n and 2n + 1, leaves from leaves_
    std::size_t leaves_ = 1;

    std::uint32_t winner(std::uint32_t a, std::uint32_t b) const {
        if (a == kNone) return b;
        if (b == kNone) return a;
        return keys_[b] > keys_[a] ? b : a;  // a < b always: the left subtree holds lower indices
    }
};

}  // namespace hemirad::solve
