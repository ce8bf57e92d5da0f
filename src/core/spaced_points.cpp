#include "core/spaced_points.hpp"

#include <cmath>

namespace lapflow::detail {
namespace {
constexpr int64_t kMargin = 2;
constexpr double kMaxDenseCells = double(1 << 23);  // 32 MiB of heads
}  // namespace

SpacedPoints::SpacedPoints(double d, const Box3& box) : d_(d), d2_(d * d), origin_(box.empty() ? Vec3{} : box.lo) {
  if (box.empty()) return;
  const Vec3 size = box.size();
  const double n[3] = {size.x / d, size.y / d, size.z / d};
  double cells = 1;
  for (int k = 0; k < 3; ++k) {
    if (!(n[k] >= 0 && n[k] < 1e8)) return;  // NaN, or far too many cells
    dims_[k] = int64_t(n[k]) + 1 + 2 * kMargin;
    cells *= double(dims_[k]);
  }
  if (cells <= kMaxDenseCells) head_.assign(std::size_t(cells), -1);
}

SpacedPoints::Cell SpacedPoints::cell_of(const Vec3& p) const {
  return {int64_t(std::floor((p.x - origin_.x) / d_)), int64_t(std::floor((p.y - origin_.y) / d_)),
          int64_t(std::floor((p.z - origin_.z) / d_))};
}

int64_t SpacedPoints::dense_slot(const Cell& c) const {
  if (head_.empty()) return -1;
  const int64_t x = c[0] + kMargin, y = c[1] + kMargin, z = c[2] + kMargin;
  if (x < 0 || y < 0 || z < 0 || x >= dims_[0] || y >= dims_[1] || z >= dims_[2]) return -1;
  return (z * dims_[1] + y) * dims_[0] + x;
}

uint64_t SpacedPoints::key(const Cell& c) {
  return (uint64_t(c[0] & 0x1fffff) << 42) | (uint64_t(c[1] & 0x1fffff) << 21) | uint64_t(c[2] & 0x1fffff);
}

bool SpacedPoints::free(const Vec3& p, int group) const {
  auto close = [&](int s) {
    if (group_[std::size_t(s)] != group || !(norm2(pos_[std::size_t(s)] - p) < d2_)) return false;
    last_blocker_ = s;
    return true;
  };
  if (last_blocker_ >= 0 && close(last_blocker_)) return false;
  const Cell c = cell_of(p);
  for (int64_t dz = -1; dz <= 1; ++dz)
    for (int64_t dy = -1; dy <= 1; ++dy)
      for (int64_t dx = -1; dx <= 1; ++dx) {
        const Cell n{c[0] + dx, c[1] + dy, c[2] + dz};
        if (const int64_t slot = dense_slot(n); slot >= 0) {
          for (int s = head_[std::size_t(slot)]; s >= 0; s = next_[std::size_t(s)])
            if (close(s)) return false;
          continue;
        }
        if (auto it = cells_.find(key(n)); it != cells_.end())
          for (int s : it->second)
            if (close(s)) return false;
      }
  return true;
}

void SpacedPoints::add(const Vec3& p, int group) {
  const int s = int(pos_.size());
  pos_.push_back(p);
  group_.push_back(group);
  const Cell c = cell_of(p);
  if (const int64_t slot = dense_slot(c); slot >= 0) {
    next_.push_back(head_[std::size_t(slot)]);
    head_[std::size_t(slot)] = s;
    return;
  }
  next_.push_back(-1);
  cells_[key(c)].push_back(s);
}

}  // namespace lapflow::detail
