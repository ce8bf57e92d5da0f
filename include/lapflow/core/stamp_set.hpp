#pragma once
/// \file stamp_set.hpp A set of small indices that empties in O(1).
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace lapflow {

/// A set over the indices [0, n), emptied by `clear` in constant time: each
/// member carries the current generation's stamp, so a walk over a mesh
/// (thousands per frame, a few hundred elements each) never touches the rest
/// of the mesh to forget the last walk. Keep one per thread and reuse it.
class StampSet {
 public:
  /// Empties the set and makes room for the indices [0, n). The array only
  /// grows; it is refilled with zeros once in 2^32 clears.
  void clear(std::size_t n) {
    if (stamp_.size() < n) stamp_.resize(n, 0);
    if (generation_ == UINT32_MAX) {
      std::fill(stamp_.begin(), stamp_.end(), 0u);
      generation_ = 0;
    }
    ++generation_;
  }
  /// Is i in the set? (i < the n of the last clear.)
  bool contains(std::size_t i) const { return stamp_[i] == generation_; }
  /// Adds i; false when it was in already.
  bool insert(std::size_t i) {
    if (stamp_[i] == generation_) return false;
    stamp_[i] = generation_;
    return true;
  }

 private:
  std::vector<uint32_t> stamp_;
  uint32_t generation_ = 0;  // stamps of members; 0 is never a live generation
};

}  // namespace lapflow
