// SpacedPoints: the "no kept point within d" grid the Poisson seeding and
// the hole seeds share. Its answer must equal a brute-force search whether a
// cell is in the dense array or in the hash map beyond it.
#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "core/spaced_points.hpp"

using namespace lapflow;
using lapflow::detail::SpacedPoints;

namespace {

struct Kept {
  Vec3 p;
  int group;
};

bool brute_free(const std::vector<Kept>& kept, const Vec3& p, int group, double d) {
  for (const Kept& k : kept)
    if (k.group == group && norm2(k.p - p) < d * d) return false;
  return true;
}

// Offers `n` runs of random points of [-1, 2]^3 in two groups, keeping the
// free ones; every answer is checked against the brute force. Returns how
// many were kept. Against a box of [0, 1]^3 most points fall outside it
// (the hash map), the rest inside (the array).
std::size_t offer_and_check(const Box3& box, double d, int n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 2.0);
  SpacedPoints grid(d, box);
  std::vector<Kept> kept;
  for (int i = 0; i < n; ++i) {
    // Runs of nearby points, as a hole's texels come: exercises the cached
    // last blocker.
    const Vec3 base{u(rng), u(rng), u(rng)};
    for (int k = 0; k < 4; ++k) {
      const Vec3 p = base + Vec3{0.3 * d * k, 0.1 * d * k, 0};
      const int group = int(rng() % 2);
      const bool expected = brute_free(kept, p, group, d);
      EXPECT_EQ(grid.free(p, group), expected) << "point " << i << "." << k;
      if (expected) {
        grid.add(p, group);
        kept.push_back({p, group});
      }
    }
  }
  EXPECT_EQ(grid.size(), kept.size());
  return kept.size();
}

}  // namespace

TEST(SpacedPoints, AgreesWithBruteForceInsideAndOutsideItsBox) {
  Box3 unit;
  unit.extend({0, 0, 0});
  unit.extend({1, 1, 1});
  const std::size_t kept = offer_and_check(unit, 0.1, 3000, 1);
  EXPECT_GT(kept, 1000u) << "too few kept for the test to mean anything";
}

TEST(SpacedPoints, AgreesWithBruteForceWithoutADenseArray) {
  // No box (all cells hashed), and a box far too fine for the array.
  offer_and_check(Box3{}, 0.1, 3000, 2);
  Box3 huge;
  huge.extend({-1e6, -1e6, -1e6});
  huge.extend({1e6, 1e6, 1e6});
  offer_and_check(huge, 0.1, 3000, 3);
}

TEST(SpacedPoints, GroupsDoNotKeepEachOtherOut) {
  Box3 unit;
  unit.extend({0, 0, 0});
  unit.extend({1, 1, 1});
  SpacedPoints grid(0.5, unit);
  grid.add({0.5, 0.5, 0.5}, 0);
  EXPECT_FALSE(grid.free({0.6, 0.5, 0.5}, 0));
  EXPECT_TRUE(grid.free({0.6, 0.5, 0.5}, 1)) << "another group's point is no obstacle";
  EXPECT_TRUE(grid.free({1.0, 0.5, 0.5}, 0)) << "exactly d away is free";
}
