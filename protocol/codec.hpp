#pragma once
/// Compiled decode and encode plans for DBC messages.
///
/// A `MessageCodec` is compiled once from a `DbcMessage`; decoding and encoding then allocate
/// nothing. Each signal is read from an 8-byte window of the payload with one load, a shift and
/// a mask (a 64-bit signal that straddles 9 bytes takes one more byte).
///
/// Semantics (docs/protocol.md):
/// - physical = raw * factor + offset, in the DBC's units. IEEE float/double signals
///   (`SIG_VALTYPE_`) are read as floats and then scaled the same way.
/// - A multiplexed signal that the frame's multiplexer value does not select decodes to NaN, as
///   does a signal whose raw value equals its declared "not available" value (`GenSigSNA`).
/// - Encoding rounds to the nearest raw value (halves away from zero) and saturates to the raw
///   range of the bit field; when the "not available" value sits at an end of that range,
///   saturation stops one short of it, so a real value never reads back as "not available".
///   NaN encodes to the "not available" raw value (or, for a signal without one, to raw 0, and
///   is counted). Bits not covered by a present signal are zero.
/// - A payload shorter than the message's declared length is rejected: nothing is read past its
///   end. A signal whose bits run past the declared length (a defect of the DBC, reported as a
///   problem by ParseDbc) decodes to NaN in every frame and is never encoded; the message's other
///   signals decode and encode as usual.

#include <cstdint>
#include <span>
#include <unordered_map>
#include <vector>

#include "protocol/dbc.hpp"

namespace pumptherm::protocol {

/// Outcome of decoding or encoding one frame.
enum class CodecStatus {
  kOk,
  kTooShort,    ///< payload shorter than `MessageCodec::min_bytes()`: nothing decoded/written
  kWrongCount,  ///< values span smaller than `MessageCodec::signal_count()`
};

/// What encoding one frame did.
struct EncodeResult {
  CodecStatus status = CodecStatus::kOk;
  std::uint16_t saturated = 0;        ///< signals clamped to their raw range
  std::uint16_t nan_without_sna = 0;  ///< NaN given for a signal with no "not available" value
};

/// The compiled plan of one message.
class MessageCodec {
 public:
  /// Compiles the plan. Throws std::invalid_argument if a signal's multiplexer switch is
  /// unknown (ParseDbc already rejects that).
  explicit MessageCodec(const DbcMessage& message);

  std::size_t signal_count() const noexcept { return signals_.size(); }
  /// Shortest payload accepted, bytes: the message's declared length.
  std::size_t min_bytes() const noexcept { return min_bytes_; }
  std::uint32_t id() const noexcept { return id_; }
  bool extended() const noexcept { return extended_; }

  /// Decodes every signal into `values` (in the message's signal order, DBC units; NaN for a
  /// signal absent by multiplexing or "not available"). No allocation, never throws.
  /// Returns kTooShort (values untouched) if `payload` is shorter than min_bytes(), kWrongCount
  /// if `values` has fewer than signal_count() elements.
  CodecStatus Decode(std::span<const std::uint8_t> payload,
                     std::span<double> values) const noexcept;

  /// Raw bits of signal `index` (unsigned, masked to its length; 0 for a signal that overhangs
  /// the declared length), and whether the frame's multiplexer values select it (never for a
  /// signal that overhangs). Precondition: payload.size() >= min_bytes(), index < signal_count().
  std::uint64_t RawBits(std::span<const std::uint8_t> payload, std::size_t index) const noexcept;
  bool IsPresent(std::span<const std::uint8_t> payload, std::size_t index) const noexcept;

  /// Encodes `values` (message signal order, DBC units) into the first min_bytes() bytes of
  /// `payload`. Multiplexed signals are written only where the given multiplexer values select
  /// them. No allocation, never throws.
  EncodeResult Encode(std::span<const double> values,
                      std::span<std::uint8_t> payload) const noexcept;

 private:
  struct SignalPlan {
    std::uint64_t mask = 0;      ///< low `length` bits set
    std::uint64_t sign_bit = 0;  ///< 0 for unsigned
    std::uint64_t sna_bits = 0;
    double factor = 1.0;
    double offset = 0.0;
    double raw_min = 0.0;  ///< saturation range for encoding (integers only)
    double raw_max = 0.0;
    std::int64_t raw_min_int = 0;    ///< the same range as integers: doubles round above 2^53
    std::int64_t raw_max_int = 0;    ///< (signed signals)
    std::uint64_t raw_max_uint = 0;  ///< (unsigned signals)
    std::uint32_t first_range = 0;   ///< into ranges_
    std::uint32_t range_count = 0;
    std::int32_t switch_index = -1;
    std::uint8_t window = 0;  ///< first byte of the 8-byte window
    std::int8_t shift = 0;    ///< LE: right shift; BE: position of the LSB (negative: 9 bytes)
    std::uint8_t length = 0;
    bool big_endian = false;
    bool has_sna = false;
    bool overhangs = false;  ///< reaches past the declared length: always NaN
    SignalValueType value_type = SignalValueType::kInteger;
  };

  /// Payload copied into a zero-padded buffer so any 8-byte window plus one byte is in bounds.
  static constexpr std::size_t kBufferBytes_ = 64 + 9;

  static std::uint64_t Extract(const SignalPlan& p, const std::uint8_t* buf) noexcept;
  static void Insert(const SignalPlan& p, std::uint64_t bits, std::uint8_t* buf) noexcept;
  double ToPhysical(const SignalPlan& p, std::uint64_t bits) const noexcept;
  std::uint64_t ToRaw(const SignalPlan& p, double value, EncodeResult& result) const noexcept;
  bool Selected(const std::uint8_t* buf, std::size_t index) const noexcept;
  bool SelectedByValues(std::span<const double> values, std::size_t index) const noexcept;
  bool InRanges(const SignalPlan& p, std::uint64_t switch_bits) const noexcept;

  std::vector<SignalPlan> signals_;
  std::vector<MuxRange> ranges_;
  std::size_t min_bytes_ = 0;
  std::uint32_t id_ = 0;
  bool extended_ = false;
  bool any_multiplexed_ = false;
};

/// Plans for every message of a DBC, found by CAN ID.
class DbcCodec {
 public:
  /// Compiles every message of `dbc` (indices follow `dbc.messages`).
  explicit DbcCodec(const Dbc& dbc);

  /// Index of the message with this ID and format, or -1. No allocation.
  int Find(std::uint32_t id, bool extended) const noexcept;
  const MessageCodec& message(std::size_t index) const noexcept { return codecs_[index]; }
  std::size_t size() const noexcept { return codecs_.size(); }

 private:
  static std::uint32_t Key(std::uint32_t id, bool extended) noexcept {
    return id | (extended ? 0x80000000u : 0u);
  }
  std::vector<MessageCodec> codecs_;
  std::unordered_map<std::uint32_t, int> by_id_;
};

}  // namespace pumptherm::protocol
