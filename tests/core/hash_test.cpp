#include <gtest/gtest.h>
#include "lapflow/core/parallel.hpp"
TEST(Hash, IsDeterministicAndSpreads) {
  EXPECT_EQ(lapflow::hash64(1, 2, 3), lapflow::hash64(1, 2, 3));
  EXPECT_NE(lapflow::hash64(1, 2, 3), lapflow::hash64(1, 2, 4));
}
