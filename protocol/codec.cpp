#include "protocol/codec.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

namespace pumptherm::protocol {

namespace {

static_assert(std::endian::native == std::endian::little, "the codec loads words little-endian");

std::uint64_t LoadLe(const std::uint8_t* p) noexcept {
  std::uint64_t v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
void StoreLe(std::uint8_t* p, std::uint64_t v) noexcept { std::memcpy(p, &v, sizeof v); }
std::uint64_t LoadBe(const std::uint8_t* p) noexcept { return __builtin_bswap64(LoadLe(p)); }
void StoreBe(std::uint8_t* p, std::uint64_t v) noexcept { StoreLe(p, __builtin_bswap64(v)); }

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
/// 2^63 and 2^64 as doubles: the first values that no longer convert to int64 / uint64.
constexpr double kTwoTo63 = 9223372036854775808.0;
constexpr double kTwoTo64 = 18446744073709551616.0;

}  // namespace

MessageCodec::MessageCodec(const DbcMessage& message)
    : min_bytes_(message.size_bytes), id_(message.id), extended_(message.extended) {
  signals_.reserve(message.signals.size());
  for (const auto& s : message.signals) {
    SignalPlan p;
    p.length = static_cast<std::uint8_t>(s.length_bits);
    p.mask = s.length_bits >= 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << s.length_bits) - 1;
    p.value_type = s.value_type;
    p.sign_bit = s.is_signed && s.value_type == SignalValueType::kInteger
                     ? std::uint64_t{1} << (s.length_bits - 1)
                     : 0;
    p.factor = s.factor;
    p.offset = s.offset;
    p.window = static_cast<std::uint8_t>(s.start_bit / 8);
    if (s.byte_order == ByteOrder::kLittleEndian) {
      p.shift = static_cast<std::int8_t>(s.start_bit % 8);
    } else {
      p.big_endian = true;
      // In the big-endian 8-byte window, bit b of byte (window + i) sits at (7 - i) * 8 + b.
      const int msb = 56 + static_cast<int>(s.start_bit % 8);
      p.shift = static_cast<std::int8_t>(msb - static_cast<int>(s.length_bits) + 1);
    }
    if (s.is_signed) {
      p.raw_min = -std::ldexp(1.0, static_cast<int>(s.length_bits) - 1);
      p.raw_max = std::ldexp(1.0, static_cast<int>(s.length_bits) - 1) - 1.0;
    } else {
      p.raw_min = 0.0;
      p.raw_max = std::ldexp(1.0, static_cast<int>(s.length_bits)) - 1.0;
    }
    p.raw_max_uint = p.mask;
    p.raw_max_int = static_cast<std::int64_t>(p.mask >> 1);
    p.raw_min_int = -p.raw_max_int - 1;
    if (s.not_available_raw) {
      p.has_sna = true;
      p.sna_bits = static_cast<std::uint64_t>(*s.not_available_raw) & p.mask;
      const std::int64_t sna = *s.not_available_raw;
      if (s.is_signed) {
        if (sna == p.raw_max_int) --p.raw_max_int;
        if (sna == p.raw_min_int) ++p.raw_min_int;
        p.raw_max = std::min(p.raw_max, static_cast<double>(p.raw_max_int));
        p.raw_min = std::max(p.raw_min, static_cast<double>(p.raw_min_int));
      } else {
        if (static_cast<std::uint64_t>(sna) == p.raw_max_uint) --p.raw_max_uint;
        if (sna == 0) p.raw_min = 1.0;
        p.raw_max = std::min(p.raw_max, static_cast<double>(p.raw_max_uint));
      }
    }
    if (!s.multiplexer_switch.empty()) {
      const int sw = message.FindSignal(s.multiplexer_switch);
      if (sw < 0) {
        throw std::invalid_argument("unknown multiplexer switch " + s.multiplexer_switch + " for " +
                                    s.name);
      }
      p.switch_index = sw;
      p.first_range = static_cast<std::uint32_t>(ranges_.size());
      p.range_count = static_cast<std::uint32_t>(s.multiplexer_ranges.size());
      ranges_.insert(ranges_.end(), s.multiplexer_ranges.begin(), s.multiplexer_ranges.end());
      any_multiplexed_ = true;
    }
    // A signal whose bits run past the declared length is never in a frame of that length.
    p.overhangs = SignalEndByte(s) > message.size_bytes;
    signals_.push_back(p);
  }
  if (min_bytes_ > 64) throw std::invalid_argument("message " + message.name + " beyond 64 bytes");
}

std::uint64_t MessageCodec::Extract(const SignalPlan& p, const std::uint8_t* buf) noexcept {
  if (!p.big_endian) {
    std::uint64_t v = LoadLe(buf + p.window) >> p.shift;
    if (p.shift + p.length > 64) v |= std::uint64_t{buf[p.window + 8]} << (64 - p.shift);
    return v & p.mask;
  }
  const std::uint64_t w = LoadBe(buf + p.window);
  if (p.shift >= 0) return (w >> p.shift) & p.mask;
  const int k = -p.shift;  // the signal's last k bits are the top bits of byte window + 8
  return ((w << k) | (buf[p.window + 8] >> (8 - k))) & p.mask;
}

void MessageCodec::Insert(const SignalPlan& p, std::uint64_t bits, std::uint8_t* buf) noexcept {
  bits &= p.mask;
  if (!p.big_endian) {
    std::uint64_t w = LoadLe(buf + p.window);
    w = (w & ~(p.mask << p.shift)) | (bits << p.shift);
    StoreLe(buf + p.window, w);
    if (p.shift + p.length > 64) {
      const int spill = 64 - p.shift;
      const auto high_mask = static_cast<std::uint8_t>(p.mask >> spill);
      buf[p.window + 8] =
          static_cast<std::uint8_t>((buf[p.window + 8] & ~high_mask) | (bits >> spill));
    }
    return;
  }
  std::uint64_t w = LoadBe(buf + p.window);
  if (p.shift >= 0) {
    w = (w & ~(p.mask << p.shift)) | (bits << p.shift);
    StoreBe(buf + p.window, w);
    return;
  }
  const int k = -p.shift;
  w = (w & ~(p.mask >> k)) | (bits >> k);
  StoreBe(buf + p.window, w);
  const auto low_mask = static_cast<std::uint8_t>(((1u << k) - 1u) << (8 - k));
  const auto low_bits = static_cast<std::uint8_t>((bits & ((1u << k) - 1u)) << (8 - k));
  buf[p.window + 8] = static_cast<std::uint8_t>((buf[p.window + 8] & ~low_mask) | low_bits);
}

double MessageCodec::ToPhysical(const SignalPlan& p, std::uint64_t bits) const noexcept {
  if (p.has_sna && bits == p.sna_bits) return kNaN;
  double raw;
  switch (p.value_type) {
    case SignalValueType::kFloat32: {
      const auto b = static_cast<std::uint32_t>(bits);
      raw = static_cast<double>(std::bit_cast<float>(b));
      break;
    }
    case SignalValueType::kFloat64:
      raw = std::bit_cast<double>(bits);
      break;
    default:
      raw = p.sign_bit != 0
                ? static_cast<double>(static_cast<std::int64_t>((bits ^ p.sign_bit) - p.sign_bit))
                : static_cast<double>(bits);
      break;
  }
  return raw * p.factor + p.offset;
}

std::uint64_t MessageCodec::ToRaw(const SignalPlan& p, double value,
                                  EncodeResult& result) const noexcept {
  if (std::isnan(value)) {
    if (p.has_sna) return p.sna_bits;
    ++result.nan_without_sna;
    if (p.value_type == SignalValueType::kFloat32) {
      return std::bit_cast<std::uint32_t>(std::numeric_limits<float>::quiet_NaN());
    }
    if (p.value_type == SignalValueType::kFloat64) return std::bit_cast<std::uint64_t>(kNaN);
    return 0;
  }
  const double scaled = p.factor != 0.0 ? (value - p.offset) / p.factor : 0.0;
  if (p.value_type == SignalValueType::kFloat64) return std::bit_cast<std::uint64_t>(scaled);
  if (p.value_type == SignalValueType::kFloat32) {
    constexpr double kMax = std::numeric_limits<float>::max();
    double clamped = scaled;
    if (std::isfinite(scaled) && std::abs(scaled) > kMax) {
      clamped = std::copysign(kMax, scaled);
      ++result.saturated;
    }
    return std::bit_cast<std::uint32_t>(static_cast<float>(clamped));
  }
  double x = std::round(scaled);
  if (x < p.raw_min) {
    x = p.raw_min;
    ++result.saturated;
  } else if (x > p.raw_max) {
    x = p.raw_max;
    ++result.saturated;
  }
  if (p.sign_bit != 0) {
    const std::int64_t r =
        x >= kTwoTo63 ? std::numeric_limits<std::int64_t>::max() : static_cast<std::int64_t>(x);
    return static_cast<std::uint64_t>(std::clamp(r, p.raw_min_int, p.raw_max_int)) & p.mask;
  }
  const std::uint64_t u = x >= kTwoTo64 ? ~std::uint64_t{0} : static_cast<std::uint64_t>(x);
  return std::min(u, p.raw_max_uint);
}

bool MessageCodec::InRanges(const SignalPlan& p, std::uint64_t switch_bits) const noexcept {
  for (std::uint32_t r = p.first_range; r < p.first_range + p.range_count; ++r) {
    if (switch_bits >= ranges_[r].low && switch_bits <= ranges_[r].high) return true;
  }
  return false;
}

bool MessageCodec::Selected(const std::uint8_t* buf, std::size_t index) const noexcept {
  const SignalPlan& p = signals_[index];
  if (p.overhangs) return false;
  if (p.switch_index < 0) return true;
  const auto sw = static_cast<std::size_t>(p.switch_index);
  return Selected(buf, sw) && InRanges(p, Extract(signals_[sw], buf));
}

bool MessageCodec::SelectedByValues(std::span<const double> values,
                                    std::size_t index) const noexcept {
  const SignalPlan& p = signals_[index];
  if (p.overhangs) return false;
  if (p.switch_index < 0) return true;
  const auto sw = static_cast<std::size_t>(p.switch_index);
  EncodeResult ignored;
  return SelectedByValues(values, sw) && InRanges(p, ToRaw(signals_[sw], values[sw], ignored));
}

CodecStatus MessageCodec::Decode(std::span<const std::uint8_t> payload,
                                 std::span<double> values) const noexcept {
  if (payload.size() < min_bytes_) return CodecStatus::kTooShort;
  if (values.size() < signals_.size()) return CodecStatus::kWrongCount;
  // Windows reach at most 8 bytes past the last byte a signal uses; only those need zeroing.
  alignas(8) std::uint8_t buf[kBufferBytes_];
  std::memcpy(buf, payload.data(), min_bytes_);
  std::memset(buf + min_bytes_, 0, 9);
  for (std::size_t i = 0; i < signals_.size(); ++i) {
    const SignalPlan& p = signals_[i];
    if (p.overhangs || (p.switch_index >= 0 && !Selected(buf, i))) {
      values[i] = kNaN;
      continue;
    }
    values[i] = ToPhysical(p, Extract(p, buf));
  }
  return CodecStatus::kOk;
}

std::uint64_t MessageCodec::RawBits(std::span<const std::uint8_t> payload,
                                    std::size_t index) const noexcept {
  if (signals_[index].overhangs) return 0;
  alignas(8) std::uint8_t buf[kBufferBytes_];
  std::memcpy(buf, payload.data(), min_bytes_);
  std::memset(buf + min_bytes_, 0, 9);
  return Extract(signals_[index], buf);
}

bool MessageCodec::IsPresent(std::span<const std::uint8_t> payload,
                             std::size_t index) const noexcept {
  alignas(8) std::uint8_t buf[kBufferBytes_];
  std::memcpy(buf, payload.data(), min_bytes_);
  std::memset(buf + min_bytes_, 0, 9);
  return Selected(buf, index);
}

EncodeResult MessageCodec::Encode(std::span<const double> values,
                                  std::span<std::uint8_t> payload) const noexcept {
  EncodeResult result;
  if (payload.size() < min_bytes_) {
    result.status = CodecStatus::kTooShort;
    return result;
  }
  if (values.size() < signals_.size()) {
    result.status = CodecStatus::kWrongCount;
    return result;
  }
  alignas(8) std::uint8_t buf[kBufferBytes_] = {};
  for (std::size_t i = 0; i < signals_.size(); ++i) {
    const SignalPlan& p = signals_[i];
    if (p.overhangs || (p.switch_index >= 0 && !SelectedByValues(values, i))) continue;
    Insert(p, ToRaw(p, values[i], result), buf);
  }
  std::memcpy(payload.data(), buf, min_bytes_);
  return result;
}

DbcCodec::DbcCodec(const Dbc& dbc) {
  codecs_.reserve(dbc.messages.size());
  for (std::size_t i = 0; i < dbc.messages.size(); ++i) {
    const DbcMessage& m = dbc.messages[i];
    codecs_.emplace_back(m);
    by_id_.emplace(Key(m.id, m.extended), static_cast<int>(i));
  }
}

int DbcCodec::Find(std::uint32_t id, bool extended) const noexcept {
  const auto it = by_id_.find(Key(id, extended));
  return it == by_id_.end() ? -1 : it->second;
}

}  // namespace pumptherm::protocol
