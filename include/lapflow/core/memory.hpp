#pragma once
/// \file memory.hpp Memory sizes: the machine's physical memory, the default
/// budget of `--max-memory`, and parsing/printing sizes such as `16G`.
#include <cstddef>
#include <string>

namespace lapflow {

/// Bytes of physical memory of this machine (sysconf), 0 when unknown.
std::size_t physical_memory();

/// The default of `--max-memory`: 80% of physical memory (8 GiB when it
/// cannot be read).
std::size_t default_memory_budget();

/// Parses a size: a number of bytes (`123456`) or a number with a binary
/// suffix K, M, G or T (optionally followed by `B` or `iB`, any case;
/// `1.5G` = 1.5 GiB). Throws UsageError naming `option` for anything else,
/// for zero and for sizes beyond 2^60 bytes.
std::size_t parse_memory_size(const std::string& text, const std::string& option = "--max-memory");

/// "512 MiB", "1.7 GiB", "3.2e+03 TiB": three significant digits.
std::string format_bytes(double bytes);

}  // namespace lapflow
