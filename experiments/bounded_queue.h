// A first-in first-out queue of at most `capacity` items between two pipeline stages
// (experiments/pipeline_stages.h): Push blocks while full, TryPush refuses, Pop blocks while
// empty (PushDroppingOldest makes room instead; it and WaitUntilBelow can keep the queue under
// a lower limit than its capacity). Close() wakes every waiter: Push/TryPush then refuse and
// Pop drains what is left before it returns false. Thread-safe for any number of producers and
// consumers. InFlightLimit (below) bounds the items between a pipeline's first and last stage;
// LiveBacklog gives a live source's queue its room while the first frame's backlog lasts.
#pragma once

#include <algorithm>
#include <condition_variable>
#include <cstddef>
#include <deque>
#include <mutex>
#include <utility>

namespace artex {

template <class T>
class BoundedQueue {
 public:
  explicit BoundedQueue(std::size_t capacity) : capacity_(capacity < 1 ? 1 : capacity) {}

  // Waits for room; false (item untouched) when the queue is closed.
  bool Push(T&& item) {
    std::unique_lock<std::mutex> lock(mutex_);
    not_full_.wait(lock, [&] { return closed_ || items_.size() < capacity_; });
    if (closed_) return false;
    items_.push_back(std::move(item));
    not_empty_.notify_one();
    return true;
  }
  // Never waits; false (item untouched) when full or closed.
  bool TryPush(T&& item) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (closed_ || items_.size() >= capacity_) return false;
    items_.push_back(std::move(item));
    not_empty_.notify_one();
    return true;
  }
  // Never waits: when full, the oldest item is dropped to make room (a live source keeps
  // the newest frames). Returns the number of items dropped (0 or 1); closed: drops `item`
  // itself and returns 1.
  int PushDroppingOldest(T&& item) { return PushDroppingOldest(std::move(item), capacity_); }
  // The same with at most `limit` items (<= capacity) kept: drops the oldest until there is
  // room under the limit; returns how many were dropped (closed: drops `item`, returns 1).
  int PushDroppingOldest(T&& item, std::size_t limit) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (closed_) return 1;
    limit = std::max<std::size_t>(1, std::min(limit, capacity_));
    int dropped = 0;
    while (items_.size() >= limit) {
      items_.pop_front();
      ++dropped;
    }
    items_.push_back(std::move(item));
    not_empty_.notify_one();
    return dropped;
  }
  // Waits for an item; false when the queue is closed and empty.
  bool Pop(T* item) {
    std::unique_lock<std::mutex> lock(mutex_);
    not_empty_.wait(lock, [&] { return closed_ || !items_.empty(); });
    if (items_.empty()) return false;
    *item = std::move(items_.front());
    items_.pop_front();
    not_full_.notify_one();
    return true;
  }
  void Close() {
    std::lock_guard<std::mutex> lock(mutex_);
    closed_ = true;
    not_full_.notify_all();
    not_empty_.notify_all();
  }
  bool closed() {
    std::lock_guard<std::mutex> lock(mutex_);
    return closed_;
  }
  std::size_t capacity() const { return capacity_; }
  // Blocks while the queue holds `limit` (<= capacity) items or more; false once it is closed.
  bool WaitUntilBelow(std::size_t limit) {
    limit = std::max<std::size_t>(1, std::min(limit, capacity_));
    std::unique_lock<std::mutex> lock(mutex_);
    not_full_.wait(lock, [&] { return closed_ || items_.size() < limit; });
    return !closed_;
  }
  std::size_t size() {
    std::lock_guard<std::mutex> lock(mutex_);
    return items_.size();
  }

 private:
  const std::size_t capacity_;
  std::mutex mutex_;
  std::condition_variable not_full_, not_empty_;
  std::deque<T> items_;
  bool closed_ = false;
};

// At most `limit` items out at once (the frames a pipeline's source has read and its last
// stage not yet finished): Acquire waits while `limit` are out, Release returns one. Close()
// wakes every waiter and makes Acquire refuse. Limit 0: no limit (Acquire never waits).
class InFlightLimit {
 public:
  explicit InFlightLimit(std::size_t limit) : limit_(limit) {}
  // Waits for room; false once closed.
  bool Acquire() {
    std::unique_lock<std::mutex> lock(mutex_);
    room_.wait(lock, [&] { return closed_ || limit_ == 0 || out_ < limit_; });
    if (closed_) return false;
    peak_ = std::max(peak_, ++out_);
    return true;
  }
  // The most items out at once so far.
  std::size_t peak() {
    std::lock_guard<std::mutex> lock(mutex_);
    return peak_;
  }
  void Release() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (out_ > 0) --out_;
    room_.notify_one();
  }
  void Close() {
    std::lock_guard<std::mutex> lock(mutex_);
    closed_ = true;
    room_.notify_all();
  }

 private:
  const std::size_t limit_;
  std::mutex mutex_;
  std::condition_variable room_;
  std::size_t out_ = 0, peak_ = 0;
  bool closed_ = false;
};

// The room of a live track stage's queue (pipeline.live_queue_depth = live_depth) while the
// first frame's backlog lasts (pipeline.live_init_queue_depth = init_depth,
// live_init_drain_every = drain_every): init_depth frames until the first frame is tracked;
// from then on at most the frames waiting plus the one being read, and falling by one every
// `drain_every` frames read, so that it only shrinks and is back to live_depth (the backlog
// over) within init_depth * drain_every frames, or as soon as the tracker has caught up.
// Not thread-safe: the reader's.
class LiveBacklog {
 public:
  LiveBacklog(std::size_t live_depth, std::size_t init_depth, int drain_every)
      : live_depth_(std::max<std::size_t>(1, live_depth)),
        limit_(std::max(live_depth_, init_depth)),
        drain_every_(std::max(1, drain_every)),
        active_(limit_ > live_depth_) {}
  // The room for the frame about to be read, `waiting` frames already in the queue.
  std::size_t Room(bool first_tracked, std::size_t waiting) {
    if (!active_) return live_depth_;
    if (first_tracked) {
      if (started_ && ++reads_ % drain_every_ == 0) --limit_;
      limit_ = std::min(limit_, waiting + 1);
      started_ = true;
      if (limit_ <= live_depth_) active_ = false;
    }
    return std::max(live_depth_, limit_);
  }
  // The backlog lasts (the room may exceed live_depth).
  bool active() const { return active_; }

 private:
  const std::size_t live_depth_;
  std::size_t limit_;
  const int drain_every_;
  bool active_;
  bool started_ = false;
  long reads_ = 0;
};

}  // namespace artex
