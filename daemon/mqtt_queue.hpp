#pragma once
/// The bounded queues of pump steps for the MQTT sink (docs/mqtt.md): fixed slots allocated
/// once, so pushing from the loop never allocates; when full, a push overwrites the oldest step
/// and says so (the sink counts it). StepQueue holds data steps until they are handed to the
/// client; AlarmRing holds alarm transitions until the broker acknowledged them. Not
/// synchronised: MqttSink holds its lock around each call.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>
#include <stdexcept>
#include <vector>

namespace pumptherm::daemon::mqtt {

/// One queued step: which pump, when (ms since the Unix epoch), the order it was pushed in
/// (across queues), and its values (MqttSink's width; a pump with fewer metrics uses a prefix).
struct QueuedStep {
  std::uint32_t device = 0;
  std::uint64_t time_ms = 0;
  std::uint64_t order = 0;
  std::size_t count = 0;
};

class StepQueue {
 public:
  /// `capacity` steps of at most `width` values each. Throws std::invalid_argument for 0.
  StepQueue(std::size_t capacity, std::size_t width)
      : width_(width), meta_(capacity), values_(capacity * width) {
    if (capacity == 0) throw std::invalid_argument("StepQueue: capacity 0");
  }

  std::size_t size() const { return count_; }
  std::size_t capacity() const { return meta_.size(); }
  bool empty() const { return count_ == 0; }

  /// Appends a step; when the queue is full the oldest step gives its slot. Returns whether
  /// one was dropped. Throws std::out_of_range for more values than the width.
  bool Push(const QueuedStep& step, std::span<const double> values) {
    if (values.size() > width_) throw std::out_of_range("StepQueue: more values than the width");
    bool dropped = false;
    if (count_ == meta_.size()) {
      head_ = (head_ + 1) % meta_.size();
      --count_;
      dropped = true;
    }
    const std::size_t slot = (head_ + count_) % meta_.size();
    meta_[slot] = step;
    meta_[slot].count = values.size();
    std::copy(values.begin(), values.end(),
              values_.begin() + static_cast<std::ptrdiff_t>(slot * width_));
    ++count_;
    return dropped;
  }

  /// The oldest step (the queue must not be empty).
  const QueuedStep& Front() const { return meta_[head_]; }
  std::span<const double> FrontValues() const {
    return {values_.data() + head_ * width_, meta_[head_].count};
  }
  void Pop() {
    if (count_ == 0) return;
    head_ = (head_ + 1) % meta_.size();
    --count_;
  }

 private:
  std::size_t width_;
  std::vector<QueuedStep> meta_;
  std::vector<double> values_;
  std::size_t head_ = 0;
  std::size_t count_ = 0;
};

/// The alarm transitions' ring: each step stays until the broker acknowledged it (the PUBACK of
/// its QoS 1 message id, in any order). Its steps are, in the order they came, first those in
/// flight on this connection (sent, message id known), then those waiting to be sent. A new
/// connection puts every step in flight back to waiting (RequeueInFlight), so that they go
/// again, in order. When full, a push drops the oldest step, whether in flight or not.
class AlarmRing {
 public:
  /// `capacity` steps of at most `width` values each. Throws std::invalid_argument for 0.
  AlarmRing(std::size_t capacity, std::size_t width)
      : width_(width), meta_(capacity), mid_(capacity, 0), values_(capacity * width) {
    if (capacity == 0) throw std::invalid_argument("AlarmRing: capacity 0");
  }

  /// Steps not acknowledged yet (in flight or waiting).
  std::size_t size() const { return count_; }
  std::size_t capacity() const { return meta_.size(); }
  bool empty() const { return count_ == 0; }
  /// Steps sent on this connection and not acknowledged yet.
  std::size_t in_flight() const { return sent_; }
  /// Whether a step waits to be sent.
  bool HasNext() const { return sent_ < count_; }

  /// Appends a step (waiting); when the ring is full the oldest step gives its slot. Returns
  /// whether one was dropped. Throws std::out_of_range for more values than the width.
  bool Push(const QueuedStep& step, std::span<const double> values) {
    if (values.size() > width_) throw std::out_of_range("AlarmRing: more values than the width");
    bool dropped = false;
    if (count_ == meta_.size()) {
      head_ = Slot(1);
      --count_;
      if (sent_ > 0) --sent_;
      dropped = true;
    }
    const std::size_t slot = Slot(count_);
    meta_[slot] = step;
    meta_[slot].count = values.size();
    mid_[slot] = 0;
    std::copy(values.begin(), values.end(),
              values_.begin() + static_cast<std::ptrdiff_t>(slot * width_));
    ++count_;
    return dropped;
  }

  /// The oldest step waiting to be sent (HasNext() must be true).
  const QueuedStep& Next() const { return meta_[Slot(sent_)]; }
  std::span<const double> NextValues() const {
    const std::size_t slot = Slot(sent_);
    return {values_.data() + slot * width_, meta_[slot].count};
  }

  /// The step Next() gave, of push order `order`, went out as message `mid`: it is in flight.
  /// Returns false (nothing marked) when that step is no longer the next one (dropped since).
  bool MarkSent(std::uint64_t order, int mid) {
    if (!HasNext() || Next().order != order) return false;
    mid_[Slot(sent_)] = mid;
    ++sent_;
    return true;
  }

  /// The broker acknowledged message `mid`: its step leaves the ring. Returns whether a step in
  /// flight had that id (an id of another message, or of a step dropped or re-queued since,
  /// matches none).
  bool Ack(int mid) {
    for (std::size_t k = 0; k < sent_; ++k) {
      if (mid_[Slot(k)] != mid) continue;
      // Close the gap: the steps before it move up one slot (the front is the common case).
      for (std::size_t j = k; j > 0; --j) Move(Slot(j - 1), Slot(j));
      head_ = Slot(1);
      --count_;
      --sent_;
      return true;
    }
    return false;
  }

  /// A new connection: every step in flight waits to be sent again, in the order they came.
  /// Returns how many were in flight.
  std::size_t RequeueInFlight() {
    const std::size_t n = sent_;
    sent_ = 0;
    return n;
  }

 private:
  std::size_t Slot(std::size_t k) const { return (head_ + k) % meta_.size(); }
  void Move(std::size_t from, std::size_t to) {
    meta_[to] = meta_[from];
    mid_[to] = mid_[from];
    std::copy_n(values_.begin() + static_cast<std::ptrdiff_t>(from * width_), meta_[from].count,
                values_.begin() + static_cast<std::ptrdiff_t>(to * width_));
  }

  std::size_t width_;
  std::vector<QueuedStep> meta_;
  std::vector<int> mid_;
  std::vector<double> values_;
  std::size_t head_ = 0;
  std::size_t count_ = 0;
  std::size_t sent_ = 0;
};

}  // namespace pumptherm::daemon::mqtt
