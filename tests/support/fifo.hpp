#pragma once

// FIFOs as inputs: a reader that opens one waits for a writer, so a test that gives one to
// a loader which should refuse it must not hang when the loader does not: FifoWatchdog
// opens every FIFO for writing (and closes it) once its time is up, so a reader that waits
// sees an empty file and the test fails instead of hanging.

#include <doctest/doctest.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <thread>
#include <utility>
#include <vector>

namespace vmap::test {

/// A new FIFO at `p` (an existing file there removed first).
inline std::filesystem::path make_fifo(const std::filesystem::path& p) {
  std::filesystem::remove(p);
  REQUIRE(::mkfifo(p.c_str(), 0600) == 0);
  return p;
}

class FifoWatchdog {
 public:
  FifoWatchdog(std::vector<std::filesystem::path> fifos, std::chrono::seconds after)
      : fifos_(std::move(fifos)), thread_([this, after] { run(after); }) {}
  FifoWatchdog(const FifoWatchdog&) = delete;
  FifoWatchdog& operator=(const FifoWatchdog&) = delete;
  ~FifoWatchdog() {
    done_ = true;
    thread_.join();
  }

 private:
  void run(std::chrono::seconds after) {
    const auto until = std::chrono::steady_clock::now() + after;
    while (!done_) {
      if (std::chrono::steady_clock::now() >= until)
        for (const auto& f : fifos_) {
          // Succeeds only while a reader has the FIFO open: that reader then reads EOF.
          const int fd = ::open(f.c_str(), O_WRONLY | O_NONBLOCK | O_CLOEXEC);
          if (fd >= 0) ::close(fd);
        }
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
  }

  std::vector<std::filesystem::path> fifos_;
  std::atomic<bool> done_{false};
  std::thread thread_;
};

}  // namespace vmap::test
