#pragma once
// Reading frames ahead: the next frame's mesh, surface query, velocity and
// atlas (step 6 needs only the mesh) are made on another thread while the
// current frame computes.
#include <future>
#include <memory>
#include <vector>

#include "lapflow/atlas/atlas.hpp"
#include "lapflow/bake/frame.hpp"

namespace lapflow::detail {

class FrameReader {
 public:
  /// Reads `frames` in order from `source`, each with its atlas; `ahead`
  /// starts each read while the previous frame is still in use.
  FrameReader(const FrameSource& source, const AtlasOptions& atlas, std::vector<int> frames, bool ahead);
  /// The next frame with its atlas built (stats.seconds_atlas is the atlas's
  /// own time). Errors of a frame's reading surface here, in frame order.
  std::shared_ptr<Frame> next();

 private:
  void start(std::size_t index);

  FrameSource source_;
  AtlasOptions atlas_;
  std::vector<int> frames_;
  bool ahead_;
  std::size_t next_index_ = 0;
  std::future<std::shared_ptr<Frame>> pending_;
};

}  // namespace lapflow::detail
