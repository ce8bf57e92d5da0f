#include "bake/read_ahead.hpp"

#include <stdexcept>

#include "lapflow/core/stopwatch.hpp"

namespace lapflow::detail {

FrameReader::FrameReader(const BakeOptions& options, std::vector<int> frames)
    : options_(options), source_(frame_source(options)), frames_(std::move(frames)), ahead_(options.prefetch_read) {
  if (ahead_) start(0);
}

void FrameReader::start(std::size_t index) {
  if (index >= frames_.size()) return;
  pending_ = std::async(ahead_ ? std::launch::async : std::launch::deferred, [this, f = frames_[index]] {
    std::shared_ptr<Frame> frame = load_frame(source_, f);
    Stopwatch clock;
    build_frame_atlases(*frame, options_);
    frame->stats.seconds_atlas = clock.lap();
    frame->stats.fresh_seeding = fresh_seeding_count(frame->mesh, frame->number, options_.patch, options_.seeding);
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
