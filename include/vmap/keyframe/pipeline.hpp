#pragma once

// Feeding a FrameSource through a selector, optionally on two threads: one decodes and
// prepares (extracts features of) frame j+1 while the other scores frame j against the
// key image. Frames reach push() in order, so the key images are the same as with one
// thread.

#include <vmap/core/error.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/keyframe/selector.hpp>

#include <condition_variable>
#include <cstddef>
#include <deque>
#include <exception>
#include <mutex>
#include <optional>
#include <thread>
#include <type_traits>
#include <utility>

namespace vmap {

struct RunOptions {
  /// Decode + prepare on a second thread (the FrameSource and the front end's
  /// preparation, e.g. the Descriptor, are then used from that thread).
  bool pipelined = true;
  std::size_t queue_capacity = 4;  ///< prepared frames waiting for push(), >= 1
};

namespace detail {

/// A bounded single-producer single-consumer queue that also carries the producer's
/// exception and end of stream.
template <class T>
class PreparedQueue {
 public:
  explicit PreparedQueue(std::size_t capacity) : capacity_(capacity) {}

  /// False when the consumer has stopped.
  bool put(T value) {
    std::unique_lock lock(mutex_);
    not_full_.wait(lock, [&] { return items_.size() < capacity_ || stopped_; });
    if (stopped_) return false;
    items_.push_back(std::move(value));
    not_empty_.notify_one();
    return true;
  }
  void finish(std::exception_ptr error) {
    std::lock_guard lock(mutex_);
    done_ = true;
    error_ = std::move(error);
    not_empty_.notify_one();
  }
  /// The next item; nullopt at the end; rethrows the producer's exception.
  std::optional<T> take() {
    std::unique_lock lock(mutex_);
    not_empty_.wait(lock, [&] { return !items_.empty() || done_; });
    if (!items_.empty()) {
      T v = std::move(items_.front());
      items_.pop_front();
      not_full_.notify_one();
      return v;
    }
    if (error_) std::rethrow_exception(error_);
    return std::nullopt;
  }
  void stop() {
    std::lock_guard lock(mutex_);
    stopped_ = true;
    not_full_.notify_all();
  }

 private:
  std::size_t capacity_;
  std::mutex mutex_;
  std::condition_variable not_full_, not_empty_;
  std::deque<T> items_;
  bool done_ = false;
  bool stopped_ = false;
  std::exception_ptr error_;
};

/// Decodes and prepares frames of `source` on a second thread (prepare(const Frame&)
/// -> T) and consumes them in order on the calling thread (consume(T&&)). The producer's
/// exceptions are rethrown here; the thread is joined however this returns.
template <class Prepare, class Consume>
void run_pipelined(FrameSource& source, std::size_t capacity, Prepare&& prepare, Consume&& consume) {
  check(capacity >= 1, "RunOptions.queue_capacity must be >= 1");
  using T = std::decay_t<decltype(prepare(std::declval<const Frame&>()))>;
  PreparedQueue<T> queue(capacity);
  std::thread producer([&] {
    try {
      while (auto frame = source.next())
        if (!queue.put(prepare(*frame))) break;
      queue.finish(nullptr);
    } catch (...) {
      queue.finish(std::current_exception());
    }
  });
  struct Joiner {
    PreparedQueue<T>& q;
    std::thread& t;
    ~Joiner() {
      q.stop();
      t.join();
    }
  } joiner{queue, producer};
  while (auto item = queue.take()) consume(std::move(*item));
}

}  // namespace detail

/// Pushes every frame of `source` through `selector`, calling on_frame(const FrameResult&)
/// after each. Exceptions of either thread (unreadable input, a policy's Error) reach
/// the caller; the second thread is always joined before returning.
template <FrameFrontEnd F, class OnFrame>
void run_selector(FrameSource& source, BasicKeyframeSelector<F>& selector, const RunOptions& options,
                  OnFrame&& on_frame) {
  if (!options.pipelined) {
    while (auto frame = source.next()) on_frame(selector.push(*frame));
    return;
  }
  detail::run_pipelined(
      source, options.queue_capacity, [&](const Frame& f) { return selector.prepare(f); },
      [&](typename BasicKeyframeSelector<F>::Prepared&& p) { on_frame(selector.push(std::move(p))); });
}

/// Same without a per-frame callback.
template <FrameFrontEnd F>
void run_selector(FrameSource& source, BasicKeyframeSelector<F>& selector, const RunOptions& options = {}) {
  run_selector(source, selector, options, [](const FrameResult&) {});
}

}  // namespace vmap
