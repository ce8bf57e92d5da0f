#pragma once
// Whole numbers read from JSON (the bake manifest, the bake state): a field
// that must be an integer of type T. nlohmann's get<int>() of 1e30 converts
// out of range (undefined behaviour) and of 2.5 truncates; these refuse both
// with an InputError naming the file and the key.
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>

#include "lapflow/core/errors.hpp"

namespace lapflow::detail {

template <typename T>
T whole_number(const nlohmann::json& v, const std::string& key, const std::string& path) {
  if (v.is_number_unsigned()) {
    if (const uint64_t u = v.get<uint64_t>(); std::in_range<T>(u)) return T(u);
  } else if (v.is_number_integer()) {
    if (const int64_t i = v.get<int64_t>(); std::in_range<T>(i)) return T(i);
  }
  throw InputError(path, "'" + key + "' must be a whole number from " + std::to_string(std::numeric_limits<T>::min()) +
                             " to " + std::to_string(std::numeric_limits<T>::max()) + ", got " + v.dump().substr(0, 40));
}

/// j[key] as a whole number, or `fallback` when j has no such key.
template <typename T>
T whole_number(const nlohmann::json& j, const std::string& key, T fallback, const std::string& path) {
  return j.contains(key) ? whole_number<T>(j.at(key), key, path) : fallback;
}

}  // namespace lapflow::detail
