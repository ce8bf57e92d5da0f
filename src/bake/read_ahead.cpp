#include "bake/read_ahead.hpp"

#include <stdexcept>

#include "lapflow/core/stopwatch.hpp"

namespace lapflow::detail {

FrameReader::FrameReader(const FrameSource& source, const AtlasOptions& atlas, std::vector<int> frames, bool ahead)
    : source_(source), atlas_(atlas), frames_(std::move(frames)), ahead_(ahead) {
  if (ahead_) start(0);
}

void FrameReader::start(std::size_t index) {
  if (index >= frames_.size()) return;
  pending_ = std::async(ahead_ ? std::launch::async : std::launch::deferred, [this, f = frames_[index]] {
    std::shared_ptr<Frame> frame = load_frame(source_, f);
    Stopwatch clock;
    frame->atlas = build_surface_atlas(frame->mesh, atlas_);
    frame->stats.seconds_atlas = clock.lap();
    return frame;
  });
}

std::shared_ptr<Frame> FrameReader::next() {
  if (next_index_ >= frames_.size()) throw std::logic_error("FrameReader: no frame left");
  if (!ahead_) start(next_index_);
  std::shared_ptr<Frame> frame = pending_.get();
  ++next_index_;
  if (ahead_) start(next_index_);
  return frame;
}

}  // namespace lapflow::detail
