// Cross-check against an independent decoder: npm's candied 2.2.0 (tests/protocol/candied/).
// For every DBC under ../shared/data/dbc/ and protocol/pumptherm.dbc, random frames of every
// message are decoded by our codec and by candied (node decode.js), and compared signal by signal:
// the signal definitions as both parsed them, the raw values and the physical values.
//
// Where candied 2.2.0 is provably wrong, the test says so and checks our answer against a hand
// computation instead:
//  1. Motorola signals longer than one bit. candied's BitUtils.extractBitRange computes the MSB's
//     position p in its MSB-first bit string (8 * floor(start / 8) + 7 - start % 8, correct) and
//     then slices bits [p - length + 1, p], the `length` bits that END at the MSB, instead of
//     [p, p + length). Example: "SG_ Be16 : 7|16@0+" on payload 12 34 gives NaN in candied
//     (negative slice index); Vector's definition (MSB = bit 7 of byte 0, then byte 1) gives
//     0x1234. Hand computation: decode.js slices candied's own bit string from p for `length`
//     bits (the "motorola raw" column) and the test compares with that.
//  2. SIG_VALTYPE_ (IEEE float/double signals): candied ignores it and returns the bits as an
//     integer. The test checks that those bits equal ours and that our value is the IEEE
//     reinterpretation of them, scaled (std::bit_cast, by hand).
//  3. Numbers in exponent notation (e.g. "(1E-005,0)"): candied's grammar rejects the SG_ line
//     and silently drops the signal. The test checks that every signal candied lacks has an
//     exponent on its SG_ line.
//  4. Raw values wider than 53 bits: candied builds them with parseInt on a bit string into a
//     double; they are compared with a relative tolerance of 1e-15 instead of exactly.
//  5. Long names (Vector's `SystemMessageLongSymbol` / `SystemSignalLongSymbol` attributes):
//     candied ignores them and names messages and signals as the BO_/SG_ statements do; the test
//     asks candied by those names and compares the same signals.
// Not a defect but a different choice: candied clamps the physical value to [min, max] when the
// DBC gives a range; DBC ranges are informational, so our codec does not clamp. Where candied
// clamped, the test checks candied's value is the clamp of ours.
#include <gtest/gtest.h>
#include <unistd.h>

#include <bit>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "protocol/codec.hpp"
#include "protocol/dbc.hpp"
#include "tests/common/run_command.hpp"
#include "tests/protocol/dbc_files.hpp"

namespace pumptherm::protocol {
namespace {

namespace fs = std::filesystem;

fs::path CandiedDir() { return test::SourceDir() / "tests" / "protocol" / "candied"; }

/// Runs a shell command and returns its stdout; `status` gets its exit code (-1: did not exit).
std::string Run(const std::string& command, int& status) {
  test_files::CommandResult r = test_files::RunCommand(command);
  status = r.exit_code;
  return std::move(r.out);
}

/// Why candied cannot run here, or empty if it can.
std::string CandiedUnavailable() {
  int status = 0;
  Run("node --version >/dev/null 2>&1", status);
  if (status != 0) return "node is not installed";
  if (!fs::exists(CandiedDir() / "node_modules" / "candied" / "package.json")) {
    return "candied is not installed: run `npm ci` in tests/protocol/candied (tools/setup.sh does)";
  }
  return "";
}

bool InCi() {
  const char* ci = std::getenv("CI");
  return ci != nullptr && std::string(ci) == "true";
}

struct CandiedDef {
  std::uint32_t start = 0;
  std::uint32_t length = 0;
  std::string endian;
  bool is_signed = false;
  double factor = 0;
  double offset = 0;
};

struct CandiedSig {
  double raw = 0;
  double value = 0;
  double motorola_raw = 0;  ///< NaN if not Motorola
};

double ParseJsNumber(const std::string& s) {
  if (s == "NaN" || s == "-") return std::numeric_limits<double>::quiet_NaN();
  if (s == "Infinity") return std::numeric_limits<double>::infinity();
  if (s == "-Infinity") return -std::numeric_limits<double>::infinity();
  return std::strtod(s.c_str(), nullptr);
}

/// candied's view of a file: definitions by "message.signal", decoded signals by frame index.
struct CandiedResult {
  std::map<std::string, CandiedDef> defs;
  std::map<std::pair<int, std::string>, CandiedSig> sigs;
};

CandiedResult RunCandied(const fs::path& dbc_path, const fs::path& frames_path) {
  int status = 0;
  const std::string out = Run("node '" + (CandiedDir() / "decode.js").string() + "' '" +
                                  dbc_path.string() + "' '" + frames_path.string() + "'",
                              status);
  EXPECT_EQ(status, 0) << "node decode.js failed on " << dbc_path;
  CandiedResult r;
  std::istringstream in(out);
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream ls(line);
    std::string kind;
    ls >> kind;
    if (kind == "def") {
      std::string msg, sig, sgn, factor, offset;
      CandiedDef d;
      ls >> msg >> sig >> d.start >> d.length >> d.endian >> sgn >> factor >> offset;
      d.is_signed = sgn == "1";
      d.factor = ParseJsNumber(factor);
      d.offset = ParseJsNumber(offset);
      r.defs[msg + "." + sig] = d;
    } else if (kind == "sig") {
      int index = 0;
      std::string sig, raw, value, moto;
      ls >> index >> sig >> raw >> value >> moto;
      r.sigs[{index, sig}] = {ParseJsNumber(raw), ParseJsNumber(value), ParseJsNumber(moto)};
    } else if (kind == "nomsg") {
      ADD_FAILURE() << "candied lacks a message: " << line;
    }
  }
  return r;
}

/// The SG_ line of a signal, to see whether candied could read its numbers.
bool LineHasExponent(const std::vector<std::string>& lines, int line) {
  if (line < 1 || static_cast<std::size_t>(line) > lines.size()) return false;
  const std::string& l = lines[static_cast<std::size_t>(line - 1)];
  for (std::size_t i = 1; i + 1 < l.size(); ++i) {
    if ((l[i] == 'e' || l[i] == 'E') && std::isdigit(static_cast<unsigned char>(l[i - 1])) &&
        (l[i + 1] == '-' || l[i + 1] == '+' ||
         std::isdigit(static_cast<unsigned char>(l[i + 1])))) {
      return true;
    }
  }
  return false;
}

bool Near(double a, double b, double rel) {
  if (a == b) return true;
  return std::abs(a - b) <= rel * std::max(std::abs(a), std::abs(b));
}

struct Tally {
  std::size_t compared = 0;
  std::size_t motorola_by_hand = 0;
  std::size_t float_by_hand = 0;
  std::size_t dropped_by_candied = 0;
  std::size_t clamped_by_candied = 0;
};

/// candied 2.2.0 ignores Vector's long-name attributes (`SystemMessageLongSymbol`,
/// `SystemSignalLongSymbol`) and names messages and signals as the BO_ and SG_ statements do (at
/// most 32 characters); our parser names them by the long names (protocol/dbc.hpp). These are the
/// statements' names, to ask candied by.
struct StatementNames {
  std::map<std::uint32_t, std::string> message;                         ///< by raw BO_ id
  std::map<std::pair<std::uint32_t, std::string>, std::string> signal;  ///< (id, long) -> short

  std::string Message(const DbcMessage& m) const {
    const auto it = message.find(RawId(m));
    return it == message.end() ? m.name : it->second;
  }
  std::string Signal(const DbcMessage& m, const DbcSignal& s) const {
    const auto it = signal.find({RawId(m), s.name});
    return it == signal.end() ? s.name : it->second;
  }
  static std::uint32_t RawId(const DbcMessage& m) { return m.id | (m.extended ? 0x80000000u : 0u); }
};

StatementNames ReadStatementNames(const std::vector<std::string>& lines) {
  static const std::regex kMessage(R"re(^BO_\s+(\d+)\s+(\w+)\s*:)re");
  static const std::regex kLongSignal(
      R"re(^BA_\s+"SystemSignalLongSymbol"\s+SG_\s+(\d+)\s+(\w+)\s+"([^"]*)")re");
  StatementNames names;
  std::smatch m;
  for (const std::string& l : lines) {
    if (std::regex_search(l, m, kMessage)) {
      names.message[static_cast<std::uint32_t>(std::stoul(m[1]))] = m[2];
    } else if (std::regex_search(l, m, kLongSignal)) {
      names.signal[{static_cast<std::uint32_t>(std::stoul(m[1])), m[3]}] = m[2];
    }
  }
  return names;
}

void CrossCheckFile(const fs::path& path, std::uint64_t seed, int frames_per_message,
                    Tally& tally) {
  SCOPED_TRACE(path.string());
  const std::string text = test::ReadFile(path);
  const Dbc dbc = ParseDbc(text, path.string());
  const DbcCodec codec(dbc);
  std::vector<std::string> lines;
  {
    std::istringstream in(text);
    std::string l;
    while (std::getline(in, l)) lines.push_back(l);
  }
  const StatementNames statement = ReadStatementNames(lines);

  // Random frames, exactly as long as each message needs.
  std::mt19937_64 rng(seed);
  std::vector<std::pair<std::size_t, std::vector<std::uint8_t>>> frames;
  const fs::path frames_path =
      fs::temp_directory_path() / ("pumptherm_candied_" + std::to_string(getpid()) + ".txt");
  {
    std::ofstream f(frames_path);
    for (std::size_t mi = 0; mi < dbc.messages.size(); ++mi) {
      for (int k = 0; k < frames_per_message; ++k) {
        std::vector<std::uint8_t> data(codec.message(mi).min_bytes());
        for (auto& b : data) b = static_cast<std::uint8_t>(rng());
        f << statement.Message(dbc.messages[mi]) << ' ';
        for (auto b : data) f << "0123456789ABCDEF"[b >> 4] << "0123456789ABCDEF"[b & 15];
        f << '\n';
        frames.emplace_back(mi, std::move(data));
      }
    }
  }
  const CandiedResult candied = RunCandied(path, frames_path);
  fs::remove(frames_path);

  // 1. Definitions as both parsed them.
  for (const auto& m : dbc.messages) {
    for (const auto& s : m.signals) {
      const auto it = candied.defs.find(statement.Message(m) + "." + statement.Signal(m, s));
      if (it == candied.defs.end()) {
        EXPECT_TRUE(LineHasExponent(lines, s.line))
            << m.name << "." << s.name << " (line " << s.line << ") missing from candied's parse";
        ++tally.dropped_by_candied;
        continue;
      }
      const CandiedDef& d = it->second;
      EXPECT_EQ(d.start, s.start_bit) << m.name << "." << s.name;
      EXPECT_EQ(d.length, s.length_bits) << m.name << "." << s.name;
      EXPECT_EQ(d.endian, s.byte_order == ByteOrder::kLittleEndian ? "Intel" : "Motorola")
          << m.name << "." << s.name;
      EXPECT_EQ(d.is_signed, s.is_signed) << m.name << "." << s.name;
      EXPECT_TRUE(Near(d.factor, s.factor, 1e-15)) << m.name << "." << s.name << " " << d.factor;
      EXPECT_TRUE(Near(d.offset, s.offset, 1e-15)) << m.name << "." << s.name << " " << d.offset;
    }
  }

  // 2. Decoded frames, signal by signal.
  for (std::size_t fi = 0; fi < frames.size(); ++fi) {
    const auto& [mi, data] = frames[fi];
    const DbcMessage& m = dbc.messages[mi];
    const MessageCodec& mc = codec.message(mi);
    std::vector<double> ours(mc.signal_count());
    ASSERT_EQ(mc.Decode(data, ours), CodecStatus::kOk);
    for (std::size_t si = 0; si < m.signals.size(); ++si) {
      const DbcSignal& s = m.signals[si];
      const auto it = candied.sigs.find({static_cast<int>(fi), statement.Signal(m, s)});
      if (it == candied.sigs.end()) continue;  // dropped by candied, counted above
      if (SignalEndByte(s) > m.size_bytes) {
        // Past the declared length: null for us in every frame, bits past the payload for candied.
        EXPECT_TRUE(std::isnan(ours[si])) << m.name << "." << s.name;
        continue;
      }
      const CandiedSig& c = it->second;
      const std::uint64_t bits = mc.RawBits(data, si);
      const std::uint64_t sign_bit = std::uint64_t{1} << (s.length_bits - 1);
      const double our_raw =
          s.is_signed ? static_cast<double>(static_cast<std::int64_t>((bits ^ sign_bit) - sign_bit))
                      : static_cast<double>(bits);
      double their_raw = c.raw;
      if (s.byte_order == ByteOrder::kBigEndian && s.length_bits > 1) {
        their_raw = c.motorola_raw;  // defect 1: candied's bit string, sliced correctly
        ++tally.motorola_by_hand;
      }
      const double rel = s.length_bits > 53 ? 1e-15 : 0.0;  // defect 4
      ASSERT_TRUE(Near(our_raw, their_raw, rel))
          << m.name << "." << s.name << " frame " << fi << ": raw ours " << our_raw << " candied "
          << their_raw;
      ++tally.compared;
      if (std::isnan(ours[si])) {
        // Absent by multiplexing, or the declared "not available" raw value.
        const bool sna = s.not_available_raw &&
                         (bits == (static_cast<std::uint64_t>(*s.not_available_raw) &
                                   (s.length_bits >= 64 ? ~0ull : (1ull << s.length_bits) - 1)));
        const bool float_nan = s.value_type != SignalValueType::kInteger;
        EXPECT_TRUE(sna || float_nan || !mc.IsPresent(data, si)) << m.name << "." << s.name;
        continue;
      }
      if (s.value_type != SignalValueType::kInteger) {  // defect 2: by hand
        const double ieee =
            s.value_type == SignalValueType::kFloat32
                ? static_cast<double>(std::bit_cast<float>(static_cast<std::uint32_t>(bits)))
                : std::bit_cast<double>(bits);
        EXPECT_EQ(ours[si], ieee * s.factor + s.offset) << m.name << "." << s.name;
        ++tally.float_by_hand;
        continue;
      }
      const double expected = their_raw * s.factor + s.offset;
      EXPECT_TRUE(Near(ours[si], expected, 1e-12) || std::abs(ours[si] - expected) < 1e-9)
          << m.name << "." << s.name << " frame " << fi << ": ours " << ours[si] << " candied raw "
          << their_raw;
      if (s.byte_order == ByteOrder::kLittleEndian || s.length_bits == 1) {
        // candied's own physical value: ours, or ours clamped to [min, max] (its choice).
        if (!Near(c.value, ours[si], 1e-12) && std::abs(c.value - ours[si]) >= 1e-9) {
          const bool has_range = !(s.minimum == 0 && s.maximum == 0);
          EXPECT_TRUE(has_range && c.value == std::clamp(ours[si], s.minimum, s.maximum))
              << m.name << "." << s.name << " frame " << fi << ": ours " << ours[si] << " candied "
              << c.value;
          ++tally.clamped_by_candied;
        }
      }
    }
  }
}

TEST(CodecCandiedTest, DecodesLikeCandiedOnEveryDbc) {
  const std::string why = CandiedUnavailable();
  if (!why.empty()) {
    if (InCi()) FAIL() << "CI=true and the cross-check cannot run: " << why;
    GTEST_SKIP() << why;
  }
  std::vector<fs::path> files = test::RealDbcFiles();
  if (files.empty()) {
    std::cout << "no shared DBC files under " << test::SharedDbcDir()
              << ": checking protocol/pumptherm.dbc only\n";
  }
  files.push_back(test::PumpthermDbc());
  // Features the real files lack: IEEE float/double, 64-bit and 9-byte signals, CAN FD 64 bytes,
  // a 29-bit ID, extended multiplexing.
  files.push_back(CandiedDir() / "features.dbc");
  Tally tally;
  std::uint64_t seed = 100;
  for (const auto& path : files) CrossCheckFile(path, seed++, 6, tally);
  EXPECT_GT(tally.float_by_hand, 0u);
  std::cout << "compared " << tally.compared << " signal values over " << files.size()
            << " files; by hand: " << tally.motorola_by_hand << " Motorola, " << tally.float_by_hand
            << " IEEE; candied dropped " << tally.dropped_by_candied
            << " exponent-notation signals; "
            << "candied clamped " << tally.clamped_by_candied << " values to [min, max]\n";
  EXPECT_GT(tally.compared, 0u);
}

TEST(CodecCandiedTest, CandiedMotorolaDefectIsReal) {
  // Pins defect 1 down so the workaround goes away when candied is fixed.
  const std::string why = CandiedUnavailable();
  if (!why.empty()) {
    if (InCi()) FAIL() << "CI=true and the cross-check cannot run: " << why;
    GTEST_SKIP() << why;
  }
  const fs::path dir = fs::temp_directory_path();
  const fs::path dbc_path = dir / ("pumptherm_moto_" + std::to_string(getpid()) + ".dbc");
  const fs::path frames_path = dir / ("pumptherm_moto_" + std::to_string(getpid()) + ".txt");
  std::ofstream(dbc_path)
      << "VERSION \"\"\nBS_:\nBU_: X\nBO_ 1 M: 8 X\n SG_ Be16 : 7|16@0+ (1,0) [0|0] \"\" X\n";
  std::ofstream(frames_path) << "M 1234000000000000\n";
  const CandiedResult r = RunCandied(dbc_path, frames_path);
  fs::remove(dbc_path);
  fs::remove(frames_path);
  const auto it = r.sigs.find({0, "Be16"});
  ASSERT_NE(it, r.sigs.end());
  EXPECT_TRUE(std::isnan(it->second.raw)) << "candied now decodes Motorola: drop the workaround";
  EXPECT_EQ(it->second.motorola_raw, 0x1234);
  const MessageCodec ours(
      ParseDbc("BO_ 1 M: 8 X\n SG_ Be16 : 7|16@0+ (1,0) [0|0] \"\" X\n", "m.dbc").messages[0]);
  const std::vector<std::uint8_t> frame = {0x12, 0x34, 0, 0, 0, 0, 0, 0};
  EXPECT_EQ(ours.RawBits(frame, 0), 0x1234u);
}

}  // namespace
}  // namespace pumptherm::protocol
