// Memory sizes: physical memory, the default budget, parsing and printing.
#include "lapflow/core/memory.hpp"

#include <fmt/format.h>
#include <unistd.h>

#include <cctype>
#include <charconv>
#include <cmath>

#include "lapflow/core/errors.hpp"

namespace lapflow {

std::size_t physical_memory() {
  const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGESIZE);
  if (pages <= 0 || page <= 0) return 0;
  return std::size_t(pages) * std::size_t(page);
}

std::size_t default_memory_budget() {
  const std::size_t physical = physical_memory();
  return physical > 0 ? std::size_t(double(physical) * 0.8) : std::size_t(8) << 30;
}

std::size_t parse_memory_size(const std::string& text, const std::string& option) {
  auto bad = [&](const std::string& why) {
    return UsageError(option + " " + text + ": " + why + " (expected bytes or a size such as 500M, 16G)");
  };
  double value = 0;
  const char* b = text.data();
  const char* e = b + text.size();
  const auto r = std::from_chars(b, e, value);
  if (r.ec != std::errc() || !std::isfinite(value)) throw bad("not a number");
  std::string unit(r.ptr, e);
  for (char& c : unit) c = char(std::toupper(static_cast<unsigned char>(c)));
  if (unit.size() > 1 && unit.ends_with("IB")) unit.resize(unit.size() - 2);
  else if (unit.size() > 1 && unit.back() == 'B') unit.pop_back();
  double scale = 1;
  if (unit == "K") scale = 0x1p10;
  else if (unit == "M") scale = 0x1p20;
  else if (unit == "G") scale = 0x1p30;
  else if (unit == "T") scale = 0x1p40;
  else if (!(unit.empty() || unit == "B")) throw bad("unknown unit '" + std::string(r.ptr, e) + "'");
  const double bytes = value * scale;
  if (!(bytes >= 1)) throw bad("must be at least one byte");
  if (bytes > 0x1p60) throw bad("too large");
  return std::size_t(bytes);
}

std::string format_bytes(double bytes) {
  static const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB"};
  int u = 0;
  while (u < 4 && std::abs(bytes) >= 1024) bytes /= 1024, ++u;
  if (u == 0) return fmt::format("{:.0f} B", bytes);
  return fmt::format("{:.3g} {}", bytes, units[u]);
}

}  // namespace lapflow
