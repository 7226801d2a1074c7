#pragma once

// The process's resident memory and its peak since a reset, from Linux's
// /proc/self/status (VmRSS, VmHWM; writing 5 to /proc/self/clear_refs resets VmHWM), for
// tests that check a reader refuses a crafted input without allocating what it claims.

#include <cstdint>
#include <fstream>
#include <optional>
#include <string>

namespace vmap::test {

/// A /proc/self/status field in bytes ("VmRSS", "VmHWM"); nullopt when there is none.
inline std::optional<std::uint64_t> status_bytes(const std::string& key) {
  std::ifstream f("/proc/self/status");
  std::string line;
  while (std::getline(f, line))
    if (line.rfind(key + ":", 0) == 0) return std::stoull(line.substr(key.size() + 1)) * 1024;
  return std::nullopt;
}

/// Runs `action` and returns how far the process's peak resident memory rose above its
/// resident memory before it; nullopt where the kernel cannot reset the peak.
inline std::optional<std::uint64_t> peak_growth(auto&& action) {
  {
    std::ofstream reset("/proc/self/clear_refs");
    reset << "5";
    if (!reset.flush()) return std::nullopt;
  }
  const auto before = status_bytes("VmRSS");
  action();
  const auto peak = status_bytes("VmHWM");
  if (!before || !peak) return std::nullopt;
  return *peak > *before ? *peak - *before : 0;
}

}  // namespace vmap::test
