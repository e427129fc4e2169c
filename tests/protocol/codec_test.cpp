// Compiled codec: hand-computed frames, a bit-by-bit oracle of the DBC bit numbering, rounding,
// saturation, "not available", multiplexing, short frames, and random round trips over every
// message of every shared DBC file.
#include "protocol/codec.hpp"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "tests/protocol/dbc_files.hpp"

namespace pumptherm::protocol {
namespace {

using Bytes = std::vector<std::uint8_t>;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

/// One message parsed from DBC text.
DbcMessage Message(const std::string& dbc_text) {
  Dbc dbc = ParseDbc(dbc_text, "test.dbc");
  EXPECT_EQ(dbc.messages.size(), 1u);
  return dbc.messages.at(0);
}

std::vector<double> Decode(const MessageCodec& codec, const Bytes& payload) {
  std::vector<double> values(codec.signal_count(), -12345.0);
  EXPECT_EQ(codec.Decode(payload, values), CodecStatus::kOk);
  return values;
}

/// The DBC bit numbering written out bit by bit, independent of the codec's word arithmetic:
/// Intel takes bit (start + i) as raw bit i; Motorola starts at the MSB and walks down a byte,
/// then to bit 7 of the next byte (the "sawtooth").
std::uint64_t OracleRaw(const Bytes& data, const DbcSignal& s) {
  const auto bit = [&](std::uint32_t pos) { return (data[pos / 8] >> (pos % 8)) & 1u; };
  std::uint64_t raw = 0;
  if (s.byte_order == ByteOrder::kLittleEndian) {
    for (std::uint32_t i = 0; i < s.length_bits; ++i)
      raw |= std::uint64_t{bit(s.start_bit + i)} << i;
    return raw;
  }
  std::uint32_t pos = s.start_bit;
  for (std::uint32_t i = 0; i < s.length_bits; ++i) {
    raw = (raw << 1) | bit(pos);
    pos = (pos % 8 == 0) ? pos + 15 : pos - 1;
  }
  return raw;
}

TEST(CodecTest, IntelAndMotorolaMatchHandComputedFrames) {
  const MessageCodec codec(
      Message("BO_ 1 M: 8 X\n"
              " SG_ U16 : 0|16@1+ (1,0) [0|0] \"\" X\n"
              " SG_ S16 : 16|16@1- (0.01,0) [0|0] \"A\" X\n"
              " SG_ Be16 : 39|16@0+ (1,0) [0|0] \"\" X\n"
              " SG_ BeNibbles : 51|8@0+ (1,0) [0|0] \"\" X\n"
              " SG_ BeSigned : 63|4@0- (2,1) [0|0] \"\" X\n"));
  // U16 = 0x1234 little endian; S16 raw 0xFFFE = -2 -> -0.02 A; Be16: byte 4 = 0x12 (MSB),
  // byte 5 = 0x34; BeNibbles: low nibble of byte 6 (0xA) is the high half, high nibble of
  // byte 7 (0xB) the low half -> 0xAB; BeSigned: high nibble of byte 7 = 0xB = -5 -> -9.
  const Bytes frame = {0x34, 0x12, 0xFE, 0xFF, 0x12, 0x34, 0x0A, 0xB0};
  const auto v = Decode(codec, frame);
  EXPECT_EQ(v[0], 0x1234);
  EXPECT_DOUBLE_EQ(v[1], -0.02);
  EXPECT_EQ(v[2], 0x1234);
  EXPECT_EQ(v[3], 0xAB);
  EXPECT_EQ(v[4], -9.0);
  // BeNibbles and BeSigned share byte 7's high nibble; encode writes both consistently.
  Bytes out(8, 0xEE);
  const EncodeResult r = codec.Encode(v, out);
  EXPECT_EQ(r.status, CodecStatus::kOk);
  EXPECT_EQ(r.saturated, 0);
  EXPECT_EQ(out, frame);
}

TEST(CodecTest, RandomLayoutsAgreeWithTheBitByBitOracle) {
  std::mt19937_64 rng(20261122);
  for (int trial = 0; trial < 3000; ++trial) {
    DbcSignal s;
    s.name = "S";
    s.length_bits = 1 + static_cast<std::uint32_t>(rng() % 64);
    s.byte_order = (rng() & 1) ? ByteOrder::kBigEndian : ByteOrder::kLittleEndian;
    s.is_signed = (rng() & 1) != 0;
    // A start bit that keeps the signal inside 64 bytes.
    for (;;) {
      s.start_bit = static_cast<std::uint32_t>(rng() % 512);
      if (SignalEndByte(s) <= 64 &&
          (s.byte_order == ByteOrder::kBigEndian || s.start_bit + s.length_bits <= 512)) {
        break;
      }
    }
    DbcMessage m;
    m.name = "M";
    m.size_bytes = SignalEndByte(s);
    m.signals.push_back(s);
    const MessageCodec codec(m);
    Bytes data(m.size_bytes);
    for (auto& b : data) b = static_cast<std::uint8_t>(rng());
    const std::uint64_t raw = codec.RawBits(data, 0);
    ASSERT_EQ(raw, OracleRaw(data, s)) << "start " << s.start_bit << " len " << s.length_bits
                                       << (s.byte_order == ByteOrder::kBigEndian ? " @0" : " @1");
    // Decoding and re-encoding gives the same raw back.
    std::vector<double> values(1);
    ASSERT_EQ(codec.Decode(data, values), CodecStatus::kOk);
    Bytes out(m.size_bytes, 0);
    codec.Encode(values, out);
    if (s.length_bits <= 53) {  // doubles hold the raw exactly
      EXPECT_EQ(codec.RawBits(out, 0), raw) << "start " << s.start_bit << " len " << s.length_bits;
    }
  }
}

TEST(CodecTest, EncodeWritesOnlyTheSignalsBits) {
  std::mt19937_64 rng(7);
  for (int trial = 0; trial < 500; ++trial) {
    DbcSignal s;
    s.name = "S";
    s.length_bits = 1 + static_cast<std::uint32_t>(rng() % 64);
    s.byte_order = (rng() & 1) ? ByteOrder::kBigEndian : ByteOrder::kLittleEndian;
    do {
      s.start_bit = static_cast<std::uint32_t>(rng() % 128);
    } while (SignalEndByte(s) > 16 ||
             (s.byte_order == ByteOrder::kLittleEndian && s.start_bit + s.length_bits > 128));
    DbcMessage m;
    m.name = "M";
    m.size_bytes = 16;
    m.signals.push_back(s);
    const MessageCodec codec(m);
    // All-ones raw: the encoded frame's set bits are exactly the oracle's walk over the signal.
    const std::vector<double> all_ones = {std::ldexp(1.0, static_cast<int>(s.length_bits)) - 1.0};
    Bytes out(16, 0);
    codec.Encode(all_ones, out);
    Bytes expected(16, 0);
    std::uint32_t pos = s.start_bit;
    for (std::uint32_t i = 0; i < s.length_bits; ++i) {
      expected[pos / 8] = static_cast<std::uint8_t>(expected[pos / 8] | (1u << (pos % 8)));
      if (s.byte_order == ByteOrder::kLittleEndian)
        ++pos;
      else
        pos = (pos % 8 == 0) ? pos + 15 : pos - 1;
    }
    ASSERT_EQ(out, expected) << "start " << s.start_bit << " len " << s.length_bits;
  }
}

TEST(CodecTest, FloatAndDoubleSignals) {
  const MessageCodec codec(
      Message("BO_ 2147483649 M: 16 X\n"
              " SG_ F : 0|32@1- (1,0) [0|0] \"\" X\n"
              " SG_ D : 71|64@0- (2,0) [0|0] \"\" X\n"
              "SIG_VALTYPE_ 2147483649 F : 1;\nSIG_VALTYPE_ 2147483649 D : 2;\n"));
  Bytes frame(16, 0);
  // 1.0f = 0x3F800000, little endian in bytes 0..3; -0.25 = 0xBFD0000000000000 big endian in
  // bytes 8..15, scaled by 2.
  frame[2] = 0x80;
  frame[3] = 0x3F;
  frame[8] = 0xBF;
  frame[9] = 0xD0;
  const auto v = Decode(codec, frame);
  EXPECT_EQ(v[0], 1.0);
  EXPECT_EQ(v[1], -0.5);
  Bytes out(16, 0);
  codec.Encode(v, out);
  EXPECT_EQ(out, frame);
}

TEST(CodecTest, EncodeRoundsHalvesAwayFromZeroAndSaturates) {
  const MessageCodec codec(
      Message("BO_ 1 M: 8 X\n"
              " SG_ U : 0|8@1+ (0.5,0) [0|0] \"\" X\n"
              " SG_ S : 8|8@1- (0.5,0) [0|0] \"\" X\n"
              " SG_ Sna : 16|8@1+ (1,0) [0|0] \"\" X\n"
              " SG_ SnaLow : 24|8@1- (1,0) [0|0] \"\" X\n"
              "BA_DEF_ SG_ \"GenSigSNA\" INT -128 255;\n"
              "BA_ \"GenSigSNA\" SG_ 1 Sna 255;\nBA_ \"GenSigSNA\" SG_ 1 SnaLow -128;\n"));
  Bytes out(8);
  auto r = codec.Encode(std::vector<double>{1.25, -1.25, 300.0, -300.0}, out);
  EXPECT_EQ(out[0], 3);                               // 2.5 -> 3
  EXPECT_EQ(static_cast<std::int8_t>(out[1]), -3);    // -2.5 -> -3
  EXPECT_EQ(out[2], 254);                             // saturated one short of the SNA 255
  EXPECT_EQ(static_cast<std::int8_t>(out[3]), -127);  // one short of the SNA -128
  EXPECT_EQ(r.saturated, 2);
  r = codec.Encode(std::vector<double>{1000.0, -1000.0, -1.0, 1000.0}, out);
  EXPECT_EQ(out[0], 255);
  EXPECT_EQ(static_cast<std::int8_t>(out[1]), -128);
  EXPECT_EQ(out[2], 0);
  EXPECT_EQ(out[3], 127);
  EXPECT_EQ(r.saturated, 4);
  r = codec.Encode(std::vector<double>{std::numeric_limits<double>::infinity(), 0.0, 0.0, 0.0},
                   out);
  EXPECT_EQ(out[0], 255);
  EXPECT_EQ(r.saturated, 1);
}

TEST(CodecTest, NanEncodesToTheNotAvailableValueAndBack) {
  const MessageCodec codec(
      Message("BO_ 1 M: 4 X\n"
              " SG_ T : 0|16@1- (0.1,-40) [0|0] \"degC\" X\n"
              " SG_ Plain : 16|8@1+ (1,0) [0|0] \"\" X\n"
              "BA_DEF_ SG_ \"GenSigSNA\" INT -32768 65535;\nBA_ \"GenSigSNA\" SG_ 1 T -32768;\n"));
  Bytes out(4, 0xFF);
  const EncodeResult r = codec.Encode(std::vector<double>{kNaN, kNaN}, out);
  EXPECT_EQ(out, (Bytes{0x00, 0x80, 0x00, 0x00}));
  EXPECT_EQ(r.nan_without_sna, 1);  // Plain has no "not available" value
  const auto v = Decode(codec, out);
  EXPECT_TRUE(std::isnan(v[0]));
  EXPECT_EQ(v[1], 0.0);
}

TEST(CodecTest, ShortFramesAreRejectedAndNeverReadPastTheirEnd) {
  const MessageCodec codec(Message("BO_ 1 M: 8 X\n SG_ Last : 56|8@1+ (1,0) [0|0] \"\" X\n"));
  EXPECT_EQ(codec.min_bytes(), 8u);
  std::vector<double> values(1, 42.0);
  for (std::size_t n = 0; n < 8; ++n) {
    // Heap buffers of exactly n bytes: ASan in CI reports any read past them.
    const Bytes shorter(n, 0x11);
    EXPECT_EQ(codec.Decode(shorter, values), CodecStatus::kTooShort) << n;
    EXPECT_EQ(values[0], 42.0);
    Bytes out(n);
    EXPECT_EQ(codec.Encode(values, out).status, CodecStatus::kTooShort);
  }
  const Bytes exact = {0, 0, 0, 0, 0, 0, 0, 0x77};
  ASSERT_EQ(codec.Decode(exact, values), CodecStatus::kOk);
  EXPECT_EQ(values[0], 0x77);
  std::vector<double> too_few;
  EXPECT_EQ(codec.Decode(exact, too_few), CodecStatus::kWrongCount);
}

TEST(CodecTest, SignalsOverhangingTheDeclaredLengthAreNullAndTheOthersDecode) {
  // As in a real file: "55|30@0+" in an 8-byte message runs from byte 6 to byte 9.
  const MessageCodec codec(Message(
      "BO_ 1 M: 8 X\n SG_ Over : 55|30@0+ (1,0) [0|0] \"\" X\n SG_ A : 0|8@1+ (1,0) [0|0] \"\" X\n"
      " SG_ B : 15|16@0- (0.5,1) [0|0] \"\" X\n SG_ Tail : 48|8@1+ (1,0) [0|0] \"\" X\n"));
  EXPECT_EQ(codec.min_bytes(), 8u);
  const Bytes frame = {0x2A, 0xFF, 0xFE, 0,
                       0,    0,    0x99, 0x55};  // exactly 8 bytes: ASan checks reads
  std::vector<double> values(4, 42.0);
  ASSERT_EQ(codec.Decode(frame, values), CodecStatus::kOk);
  EXPECT_TRUE(std::isnan(values[0]));
  EXPECT_EQ(values[1], 0x2A);
  EXPECT_EQ(values[2], -2 * 0.5 + 1);  // raw 0xFFFE = -2
  EXPECT_EQ(values[3], 0x99);
  EXPECT_FALSE(codec.IsPresent(frame, 0));
  EXPECT_EQ(codec.RawBits(frame, 0), 0u);
  // Encoding leaves its bits zero and writes the others.
  Bytes out(8, 0xEE);
  const std::vector<double> in = {12345, 7, 0.5, 1};
  ASSERT_EQ(codec.Encode(in, out).status, CodecStatus::kOk);
  EXPECT_EQ(out, (Bytes{7, 0xFF, 0xFF, 0, 0, 0, 1, 0}));
  // A multiplexer that overhangs selects nothing.
  const MessageCodec muxed(
      Message("BO_ 1 M: 1 X\n SG_ Mux M : 8|8@1+ (1,0) [0|0] \"\" X\n"
              " SG_ A m0 : 0|8@1+ (1,0) [0|0] \"\" X\n"));
  std::vector<double> two(2);
  ASSERT_EQ(muxed.Decode(Bytes{5}, two), CodecStatus::kOk);
  EXPECT_TRUE(std::isnan(two[0]));
  EXPECT_TRUE(std::isnan(two[1]));
}

TEST(CodecTest, MultiplexedSignalsAreNanUnlessSelected) {
  const MessageCodec codec(
      Message("BO_ 1 M: 8 X\n"
              " SG_ Mux M : 0|8@1+ (1,0) [0|0] \"\" X\n"
              " SG_ A m0 : 8|16@1+ (1,0) [0|0] \"\" X\n"
              " SG_ B m1 : 8|16@1+ (1,0) [0|0] \"\" X\n"
              " SG_ Sub m2M : 8|8@1+ (1,0) [0|0] \"\" X\n"
              " SG_ C : 16|8@1+ (1,0) [0|0] \"\" X\n"
              "SG_MUL_VAL_ 1 C Sub 3-5, 7-7;\nSG_MUL_VAL_ 1 Sub Mux 2-2;\n"));
  auto v = Decode(codec, Bytes{0, 0x34, 0x12, 0, 0, 0, 0, 0});
  EXPECT_EQ(v[1], 0x1234);
  EXPECT_TRUE(std::isnan(v[2]));
  EXPECT_TRUE(std::isnan(v[3]));
  EXPECT_TRUE(std::isnan(v[4]));
  v = Decode(codec, Bytes{2, 4, 9, 0, 0, 0, 0, 0});
  EXPECT_TRUE(std::isnan(v[1]));
  EXPECT_EQ(v[3], 4);
  EXPECT_EQ(v[4], 9);  // Sub = 4 lies in 3-5
  v = Decode(codec, Bytes{2, 6, 9, 0, 0, 0, 0, 0});
  EXPECT_TRUE(std::isnan(v[4]));  // Sub = 6 lies in no range
  v = Decode(codec, Bytes{1, 7, 9, 0, 0, 0, 0, 0});
  EXPECT_TRUE(std::isnan(v[4]));  // Sub itself is not selected by Mux = 1
  // Encoding writes only what the given multiplexer values select.
  Bytes out(8);
  codec.Encode(std::vector<double>{1, 0x5555, 0x0102, 7, 9}, out);
  EXPECT_EQ(out, (Bytes{1, 0x02, 0x01, 0, 0, 0, 0, 0}));
  codec.Encode(std::vector<double>{2, 0x5555, 0x0102, 7, 9}, out);
  EXPECT_EQ(out, (Bytes{2, 7, 9, 0, 0, 0, 0, 0}));
}

TEST(CodecTest, DbcCodecFindsMessagesById) {
  const Dbc dbc =
      ParseDbc("BO_ 256 A: 8 X\nBO_ 2147483904 B: 8 X\n", "t.dbc");  // 0x100 standard and extended
  const DbcCodec codec(dbc);
  ASSERT_EQ(codec.size(), 2u);
  EXPECT_EQ(codec.Find(0x100, false), 0);
  EXPECT_EQ(codec.Find(0x100, true), 1);
  EXPECT_EQ(codec.Find(0x101, false), -1);
}

/// Decode -> encode -> decode over random frames: the same raw bits and values come back.
void RoundTripEveryMessage(const Dbc& dbc, std::uint64_t seed, int frames_per_message) {
  const DbcCodec codec(dbc);
  std::mt19937_64 rng(seed);
  for (std::size_t mi = 0; mi < dbc.messages.size(); ++mi) {
    const DbcMessage& m = dbc.messages[mi];
    const MessageCodec& mc = codec.message(mi);
    std::vector<double> first(mc.signal_count()), second(mc.signal_count());
    for (int f = 0; f < frames_per_message; ++f) {
      Bytes data(mc.min_bytes());
      for (auto& b : data) b = static_cast<std::uint8_t>(rng());
      ASSERT_EQ(mc.Decode(data, first), CodecStatus::kOk);
      Bytes out(mc.min_bytes());
      ASSERT_EQ(mc.Encode(first, out).status, CodecStatus::kOk);
      ASSERT_EQ(mc.Decode(out, second), CodecStatus::kOk);
      for (std::size_t i = 0; i < m.signals.size(); ++i) {
        const DbcSignal& s = m.signals[i];
        SCOPED_TRACE(dbc.file_name + " " + m.name + "." + s.name);
        if (std::isnan(first[i])) {
          EXPECT_TRUE(std::isnan(second[i]));
          continue;
        }
        if (s.value_type == SignalValueType::kInteger && s.length_bits <= 53) {
          EXPECT_EQ(mc.RawBits(out, i), mc.RawBits(data, i));
          EXPECT_EQ(second[i], first[i]);
        } else {  // floats scaled back and forth, and raws beyond a double's 53 bits
          EXPECT_NEAR(second[i], first[i], 1e-12 * std::abs(first[i]) + 1e-300);
        }
      }
    }
  }
}

TEST(CodecTest, RandomFramesRoundTripForEveryRealDbc) {
  const auto files = test::RealDbcFiles();
  if (files.empty()) GTEST_SKIP() << "no DBC files under " << test::SharedDbcDir();
  std::uint64_t seed = 1;
  for (const auto& path : files) {
    const Dbc dbc = ParseDbc(test::ReadFile(path), path.string());
    RoundTripEveryMessage(dbc, seed++, 20);
  }
}

}  // namespace
}  // namespace pumptherm::protocol
