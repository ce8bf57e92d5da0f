#pragma once
// Reading frames ahead: the next frame's mesh, surface query, velocity and
// atlas (step 6 needs only the mesh) are made on another thread while the
// current frame computes.
#include <future>
#include <memory>
#include <vector>

#include "lapflow/bake/bake.hpp"

namespace lapflow::detail {

class FrameReader {
 public:
  /// Reads `frames` in order as `options` say, each with its atlas and the
  /// size of a fresh seeding (FrameStats::fresh_seeding); with
  /// BakeOptions::prefetch_read each read starts while the previous frame is
  /// still in use.
  FrameReader(const BakeOptions& options, std::vector<int> frames);
  /// The next frame with its atlas built (stats.seconds_atlas is the atlas's
  /// own time). Errors of a frame's reading surface here, in frame order.
  std::shared_ptr<Frame> next();

 private:
  void start(std::size_t index);

  const BakeOptions& options_;
  FrameSource source_;
  std::vector<int> frames_;
  bool ahead_;
  std::size_t next_index_ = 0;
  std::future<std::shared_ptr<Frame>> pending_;
};

}  // namespace lapflow::detail
