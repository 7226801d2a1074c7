#pragma once

// Feeding a FrameSource through a selector, optionally on several threads: preparing
// threads decode frames (image files in parallel; a video one frame at a time, as it is
// sequential) and extract their features (in parallel, each thread with its own copy
// of the Descriptor), while the calling thread scores frame j against the key image.
// Frames reach push() in order, so the key images are the same as with one thread.

#include <vmap/core/error.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/keyframe/selector.hpp>

#include <concepts>
#include <condition_variable>
#include <cstddef>
#include <exception>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <thread>
#include <type_traits>
#include <utility>
#include <variant>
#include <vector>

namespace vmap {

struct RunOptions {
  /// Decode + prepare on other threads than the one that scores (the FrameSource and
  /// the front end's preparation, e.g. the Descriptor, are then used from those threads).
  bool pipelined = true;
  /// Threads that decode + prepare when pipelined, >= 1. Each one beyond the first
  /// prepares with its own copy of the front end (a front end that cannot be copied
  /// uses one). Two on a 2-core machine: extraction, the largest step, then runs on
  /// both cores while the scoring thread, which mostly waits, takes what is left.
  std::size_t prepare_threads = 2;
  std::size_t queue_capacity = 4;  ///< prepared frames waiting for push(), >= prepare_threads
};

namespace detail {

/// Prepared items of several producers, handed to one consumer in frame order
/// (sequence numbers 0, 1, ...), with at most `capacity` items ahead of the consumer.
/// Also carries the first failure (at the sequence number where it happened) and the
/// end of the stream.
template <class T>
class OrderedQueue {
 public:
  explicit OrderedQueue(std::size_t capacity) : capacity_(capacity) {}

  /// Waits until item `seq` fits in the window; false when the consumer has stopped.
  bool put(std::size_t seq, T value) {
    std::unique_lock lock(mutex_);
    not_full_.wait(lock, [&] { return seq < next_ + capacity_ || stopped_; });
    if (stopped_) return false;
    items_.emplace(seq, std::move(value));
    if (seq == next_) ready_.notify_one();
    return true;
  }
  /// Frame `seq` failed: the consumer gets every earlier item, then the exception.
  void fail(std::size_t seq, std::exception_ptr error) {
    std::lock_guard lock(mutex_);
    if (!error_ || seq < error_seq_) {
      error_ = std::move(error);
      error_seq_ = seq;
    }
    ready_.notify_one();
  }
  /// The stream has `count` items.
  void end(std::size_t count) {
    std::lock_guard lock(mutex_);
    end_ = count;
    ready_.notify_one();
  }
  /// The next item in order; nullopt at the end; rethrows a failure when its turn comes.
  std::optional<T> take() {
    std::unique_lock lock(mutex_);
    ready_.wait(lock, [&] {
      return items_.count(next_) > 0 || (error_ && error_seq_ == next_) || (end_ && *end_ == next_);
    });
    if (const auto it = items_.find(next_); it != items_.end()) {
      T v = std::move(it->second);
      items_.erase(it);
      ++next_;
      not_full_.notify_all();
      return v;
    }
    if (error_ && error_seq_ == next_) std::rethrow_exception(error_);
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
  std::condition_variable not_full_, ready_;
  std::map<std::size_t, T> items_;  // at most `capacity` entries
  std::size_t next_ = 0;            // the consumer's next sequence number
  std::optional<std::size_t> end_;
  std::exception_ptr error_;
  std::size_t error_seq_ = 0;
  bool stopped_ = false;
};

/// Decodes frames of `source` and prepares them on prepares.size() threads (thread k
/// calls prepares[k](const Frame&) -> T), and consumes them in order on the calling
/// thread (consume(T&&)). Frames are claimed from the source one thread at a time and
/// decoded in parallel (image files; a video is read in order while claiming, and its
/// unreadable frames recorded then); the calling thread records each outcome in order,
/// so skipped frames are reported as FrameSource::next() reports them. Exceptions of
/// any thread are rethrown here after the frames before them were consumed; the threads
/// are joined however this returns.
template <class T, class Consume>
void run_pipelined_on(FrameSource& source, std::size_t capacity,
                      std::vector<std::function<T(const Frame&)>>& prepares, Consume&& consume) {
  check(!prepares.empty(), "RunOptions.prepare_threads must be >= 1");
  check(capacity >= prepares.size(), "RunOptions.queue_capacity must be >= the number of preparing threads");
  // A prepared frame (its image released: only the outcome is recorded), or a skipped one.
  struct Item {
    std::optional<T> value;
    std::variant<Frame, SkippedFrame> outcome;
  };
  OrderedQueue<Item> queue(capacity);
  std::mutex source_mutex;   // claim() and record() of the source
  std::size_t read = 0;      // frames claimed from the source so far
  bool source_over = false;  // ended or failed: nobody claims further
  auto produce = [&](std::function<T(const Frame&)>& prepare) {
    while (true) {
      std::optional<PendingFrame> pending;
      std::size_t seq = 0;
      {
        std::lock_guard lock(source_mutex);
        if (source_over) return;
        seq = read;
        try {
          pending = source.claim();
        } catch (...) {
          source_over = true;
          queue.fail(seq, std::current_exception());
          return;
        }
        if (!pending) {
          source_over = true;
          queue.end(seq);
          return;
        }
        ++read;
      }
      try {
        Item item{std::nullopt, source.decode(std::move(*pending))};
        if (auto* frame = std::get_if<Frame>(&item.outcome)) {
          item.value.emplace(prepare(*frame));
          frame->image.release();
        }
        if (!queue.put(seq, std::move(item))) return;
      } catch (...) {
        queue.fail(seq, std::current_exception());
        return;
      }
    }
  };
  std::vector<std::thread> threads;
  struct Joiner {
    OrderedQueue<Item>& q;
    std::vector<std::thread>& t;
    ~Joiner() {
      q.stop();
      for (auto& x : t) x.join();
    }
  } joiner{queue, threads};
  for (auto& p : prepares) threads.emplace_back(produce, std::ref(p));
  while (auto item = queue.take()) {
    {
      std::lock_guard lock(source_mutex);
      source.record(item->outcome);
    }
    if (item->value) consume(std::move(*item->value));
  }
  std::lock_guard lock(source_mutex);
  source.finish();
}

/// The same with one preparing thread.
template <class Prepare, class Consume>
void run_pipelined(FrameSource& source, std::size_t capacity, Prepare&& prepare, Consume&& consume) {
  using T = std::decay_t<decltype(prepare(std::declval<const Frame&>()))>;
  std::vector<std::function<T(const Frame&)>> prepares{[&](const Frame& f) { return prepare(f); }};
  run_pipelined_on<T>(source, capacity, prepares, consume);
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
  using Prepared = typename BasicKeyframeSelector<F>::Prepared;
  detail::check(options.prepare_threads >= 1, "RunOptions.prepare_threads must be >= 1");
  std::vector<std::function<Prepared(const Frame&)>> prepares{[&](const Frame& f) { return selector.prepare(f); }};
  auto consume = [&](Prepared&& p) { on_frame(selector.push(std::move(p))); };
  if constexpr (std::copy_constructible<F>) {
    std::vector<typename BasicKeyframeSelector<F>::Preparer> copies;
    copies.reserve(options.prepare_threads - 1);  // no reallocation: the threads hold references
    for (std::size_t k = 1; k < options.prepare_threads; ++k) copies.push_back(selector.preparer());
    for (auto& c : copies) prepares.emplace_back([&c](const Frame& f) { return c.prepare(f); });
    detail::run_pipelined_on<Prepared>(source, options.queue_capacity, prepares, consume);
  } else {
    detail::run_pipelined_on<Prepared>(source, options.queue_capacity, prepares, consume);
  }
}

/// Same without a per-frame callback.
template <FrameFrontEnd F>
void run_selector(FrameSource& source, BasicKeyframeSelector<F>& selector, const RunOptions& options = {}) {
  run_selector(source, selector, options, [](const FrameResult&) {});
}

}  // namespace vmap
