// StampSet: the O(1)-clear index set the mesh walks share.
#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "lapflow/core/stamp_set.hpp"

using namespace lapflow;

TEST(StampSet, InsertReportsNewMembersOnly) {
  StampSet s;
  s.clear(10);
  EXPECT_FALSE(s.contains(3));
  EXPECT_TRUE(s.insert(3));
  EXPECT_TRUE(s.contains(3));
  EXPECT_FALSE(s.insert(3)) << "second insert of the same index";
  EXPECT_FALSE(s.contains(4));
  s.clear(10);
  EXPECT_FALSE(s.contains(3)) << "clear forgets the last walk";
  EXPECT_TRUE(s.insert(3));
}

TEST(StampSet, AgreesWithAPlainSetOverManyWalksOfChangingSize) {
  // Walks over meshes of changing size (a new fluid mesh each frame): the
  // stamps of a larger mesh's walk must not leak into a smaller one's, nor the
  // grown part start as members.
  std::mt19937 rng(7);
  StampSet s;
  for (int walk = 0; walk < 2000; ++walk) {
    const std::size_t n = 1 + rng() % 300;
    s.clear(n);
    std::vector<bool> ref(n, false);
    for (int op = 0; op < 40; ++op) {
      const std::size_t i = rng() % n;
      ASSERT_EQ(s.contains(i), bool(ref[i])) << "walk " << walk << " index " << i;
      ASSERT_EQ(s.insert(i), !ref[i]) << "walk " << walk << " index " << i;
      ref[i] = true;
    }
    for (std::size_t i = 0; i < n; ++i) ASSERT_EQ(s.contains(i), bool(ref[i])) << "walk " << walk;
  }
}
