#pragma once
// Points kept a minimum distance apart: the question "is any kept point
// closer than d to p?" that the Poisson seeding (patches/seed.cpp) and the
// hole seeds (raster/holes.cpp) ask for every candidate, serially, so that
// the answer does not depend on the thread count.
#include <array>
#include <cstdint>
#include <unordered_map>
#include <vector>

#include "lapflow/core/vec.hpp"

namespace lapflow::detail {

/// Kept points bucketed on cells of the minimum distance d. Over a box (the
/// mesh's, two cells of margin) the cells are a dense array of per-cell
/// lists; a cell outside it (a box too large for the array, or a point
/// rounded past the box) goes to a hash map. Either way `free` answers the
/// same question, so the kept points do not depend on which holds a cell.
/// Each point has a group (the seeding's connected component): only points
/// of the same group keep each other out. One thread at a time, `free`
/// included (it caches its last blocker).
class SpacedPoints {
 public:
  SpacedPoints(double d, const Box3& box);
  /// True when no kept point of `group` lies closer than d to p.
  bool free(const Vec3& p, int group = 0) const;
  /// Keeps p (whether or not it is free).
  void add(const Vec3& p, int group = 0);
  std::size_t size() const { return pos_.size(); }

 private:
  using Cell = std::array<int64_t, 3>;
  Cell cell_of(const Vec3& p) const;
  int64_t dense_slot(const Cell& c) const;  // index into head_, or -1
  static uint64_t key(const Cell& c);

  double d_, d2_;
  Vec3 origin_;
  std::array<int64_t, 3> dims_{0, 0, 0};
  std::vector<Vec3> pos_;
  std::vector<int> group_;
  std::vector<int> head_, next_;  // per dense cell its last point, per point the one added before it
  std::unordered_map<uint64_t, std::vector<int>> cells_;
  // Candidates often come in runs (a hole's texels in row order): the point
  // that kept the last one out is asked first. The answer is the same.
  mutable int last_blocker_ = -1;
};

}  // namespace lapflow::detail
