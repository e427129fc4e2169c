#pragma once
/// A bounded queue of pump steps for the MQTT sink (docs/mqtt.md): fixed slots allocated once,
/// so pushing from the loop never allocates; when full, a push overwrites the oldest step and
/// says so (the sink counts it). Not synchronised: MqttSink holds its lock around each call.

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

}  // namespace pumptherm::daemon::mqtt
