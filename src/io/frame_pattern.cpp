// Per-frame file names: the patterns Houdini, Blender and Nuke users type.
#include <algorithm>
#include <charconv>
#include <filesystem>
#include <regex>

#include "lapflow/core/errors.hpp"
#include "lapflow/io/mesh_io.hpp"

namespace lapflow {
namespace fs = std::filesystem;

namespace {
std::string frame_digits(int frame, int width) {
  std::string d = std::to_string(frame < 0 ? -int64_t(frame) : int64_t(frame));
  if (int(d.size()) < width) d.insert(0, std::size_t(width) - d.size(), '0');
  return frame < 0 ? "-" + d : d;
}

bool parse_int(std::string_view s, int& v) {
  const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  return !s.empty() && r.ec == std::errc() && r.ptr == s.data() + s.size();
}
}  // namespace

FramePattern::FramePattern(std::string pattern) : pattern_(std::move(pattern)) {
  // printf (%04d, %d), one '#' per digit, Houdini $F4 / $F. The last token
  // wins so that a '#' or '%' in a folder name does not capture the frame.
  static const std::regex token(R"((%(0?)(\d*)d)|(#+)|(\$F(\d*)))");
  std::smatch last;
  bool found = false;
  for (auto it = std::sregex_iterator(pattern_.begin(), pattern_.end(), token); it != std::sregex_iterator(); ++it) {
    last = *it;
    found = true;
  }
  if (!found) return;
  if (last[1].matched) {
    const std::string digits = last[3].str();
    if (!digits.empty() && last[2].str().empty())
      throw UsageError("frame pattern '" + pattern_ + "': '" + last[1].str() +
                       "' pads with spaces; use '%0" + digits + "d' for zero padding or '%d'");
    width_ = digits.empty() ? 0 : std::stoi(digits);
  } else if (last[4].matched) {
    width_ = int(last[4].length());
  } else {
    width_ = last[6].length() ? std::stoi(last[6].str()) : 0;
  }
  prefix_ = pattern_.substr(0, std::size_t(last.position(0)));
  suffix_ = pattern_.substr(std::size_t(last.position(0) + last.length(0)));
  if (suffix_.find('/') != std::string::npos)
    throw UsageError("frame pattern '" + pattern_ + "': the frame token must be in the file name, not a folder");
}

std::string FramePattern::path(int frame) const {
  if (width_ < 0) return pattern_;
  return prefix_ + frame_digits(frame, width_) + suffix_;
}

std::vector<int> FramePattern::frames_on_disk() const {
  std::error_code ec;
  if (width_ < 0) {
    if (fs::is_regular_file(pattern_, ec)) return {1};
    return {};
  }
  const std::size_t slash = prefix_.rfind('/');
  const std::string dir = slash == std::string::npos ? "." : (slash == 0 ? "/" : prefix_.substr(0, slash));
  const std::string head = slash == std::string::npos ? prefix_ : prefix_.substr(slash + 1);
  std::vector<int> frames;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.size() <= head.size() + suffix_.size() || name.compare(0, head.size(), head) != 0 ||
        name.compare(name.size() - suffix_.size(), suffix_.size(), suffix_) != 0)
      continue;
    int frame;
    if (!parse_int(std::string_view(name).substr(head.size(), name.size() - head.size() - suffix_.size()), frame))
      continue;
    // Round trip: `%04d` must not also pick up `name.1.ply` or `name.00001.ply`.
    if (head + frame_digits(frame, width_) + suffix_ != name) continue;
    std::error_code fe;
    if (!it->is_regular_file(fe)) continue;
    frames.push_back(frame);
  }
  std::sort(frames.begin(), frames.end());
  frames.erase(std::unique(frames.begin(), frames.end()), frames.end());
  return frames;
}

FrameRange parse_frame_range(const std::string& text) {
  // "A-B" or "A"; a leading '-' on either number is a negative frame.
  const std::size_t dash = text.find('-', 1);
  FrameRange r;
  const bool ok = dash == std::string::npos
                      ? parse_int(text, r.first) && (r.last = r.first, true)
                      : parse_int(std::string_view(text).substr(0, dash), r.first) &&
                            parse_int(std::string_view(text).substr(dash + 1), r.last);
  if (!ok) throw UsageError("invalid frame range '" + text + "': expected A-B (e.g. 1-100) or a single frame");
  if (r.last < r.first)
    throw UsageError("invalid frame range '" + text + "': the last frame comes before the first");
  return r;
}

std::vector<int> resolve_frames(const FramePattern& pattern, const std::optional<FrameRange>& range) {
  std::error_code ec;
  if (!pattern.has_frame_token()) {
    if (range && (range->first != 1 || range->last != 1))
      throw UsageError("'" + pattern.pattern() +
                       "' has no frame token (%04d, ####, $F4): it is one file, and --frames cannot select frames from it");
    if (!fs::is_regular_file(pattern.pattern(), ec)) throw InputError(pattern.pattern(), "file not found");
    return {1};
  }
  if (!range) {
    std::vector<int> frames = pattern.frames_on_disk();
    if (frames.empty()) throw InputError(pattern.pattern(), "no file matches this frame pattern");
    return frames;
  }
  std::vector<int> frames;
  for (int64_t f = range->first; f <= range->last; ++f) {
    const std::string p = pattern.path(int(f));
    if (!fs::is_regular_file(p, ec))
      throw InputError(p, "file not found: frame " + std::to_string(f) + " is missing from the range " +
                              std::to_string(range->first) + "-" + std::to_string(range->last),
                       int(f));
    frames.push_back(int(f));
  }
  return frames;
}

}  // namespace lapflow
