// Cross-check against an independent decoder: Debian's python3-canmatrix (tests/protocol/
// canmatrix/decode.py). For every DBC under ../shared/data/dbc/, protocol/pumptherm.dbc and
// tests/protocol/candied/features.dbc, random frames of every message (its declared length) are
// decoded by our codec and by canmatrix, and every value that both produce is compared: the raw
// value exactly (integer signals) and the physical value to 1e-12 relative (canmatrix scales in
// Python's Decimal, we in double).
//
// Where only one side gives a value, the test says why and checks it:
//  - ours null, canmatrix a number: the signal overhangs the declared length (we decode it as
//    not available; canmatrix reads the missing bytes as zeros), or the raw value is the declared
//    GenSigSNA (canmatrix has no "not available"), or an IEEE NaN.
//  - canmatrix lacks a signal we decode: canmatrix could not read its SG_ line (it logs and drops
//    it, e.g. vw_pq.dbc's lone "m" multiplexer indicator), counted.
// Figures (docs/protocol.md) are printed at the end.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
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

/// Debian's canmatrix is installed for the system Python, not for one found first on PATH.
constexpr const char* kPython = "/usr/bin/python3";

fs::path Script() { return test::SourceDir() / "tests" / "protocol" / "canmatrix" / "decode.py"; }

/// Runs a shell command and returns its stdout; `status` gets its exit code (-1: did not exit).
std::string Run(const std::string& command, int& status) {
  test_files::CommandResult r = test_files::RunCommand(command);
  status = r.exit_code;
  return std::move(r.out);
}

/// Why canmatrix cannot run here, or empty if it can.
std::string CanmatrixUnavailable() {
  int status = 0;
  Run(std::string(kPython) + " -c 'import canmatrix.formats' >/dev/null 2>&1", status);
  if (status != 0) return "python3-canmatrix is not installed (tools/setup.sh installs it)";
  return "";
}

bool InCi() {
  const char* ci = std::getenv("CI");
  return ci != nullptr && std::string(ci) == "true";
}

struct TheirValue {
  double raw = 0;
  double physical = 0;
};

/// canmatrix's values by (frame index, signal name); frames whose ID it lacks in `missing`.
struct Theirs {
  std::map<std::pair<int, std::string>, TheirValue> values;
  std::map<int, std::string> message_names;  ///< by frame index
  std::size_t missing = 0;
  std::size_t padded = 0;
};

double ParsePyNumber(const std::string& s) {
  if (s == "nan") return std::numeric_limits<double>::quiet_NaN();
  if (s == "inf") return std::numeric_limits<double>::infinity();
  if (s == "-inf") return -std::numeric_limits<double>::infinity();
  return std::strtod(s.c_str(), nullptr);
}

/// Runs decode.py once on every (DBC, frames) pair; canmatrix's answer for each pair.
std::vector<Theirs> RunCanmatrix(const std::vector<std::pair<fs::path, fs::path>>& pairs) {
  std::string command = std::string(kPython) + " '" + Script().string() + "'";
  for (const auto& [dbc, frames] : pairs)
    command += " '" + dbc.string() + "' '" + frames.string() + "'";
  int status = 0;
  const std::string out = Run(command + " 2>/dev/null", status);
  EXPECT_EQ(status, 0) << "decode.py failed: " << command;
  std::vector<Theirs> all;
  std::istringstream in(out);
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream ls(line);
    std::string kind, name, raw, phys;
    int index = 0;
    ls >> kind >> index;
    if (kind == "file") {
      all.emplace_back();
    } else if (all.empty()) {
      ADD_FAILURE() << "decode.py: output before the first file: " << line;
    } else if (kind == "nomsg") {
      ++all.back().missing;
    } else if (kind == "padded") {
      ++all.back().padded;
    } else if (kind == "msg") {
      ls >> name;
      all.back().message_names[index] = name;
    } else if (kind == "sig") {
      ls >> name >> raw >> phys;
      all.back().values[{index, name}] = {ParsePyNumber(raw), ParsePyNumber(phys)};
    }
  }
  EXPECT_EQ(all.size(), pairs.size());
  all.resize(pairs.size());
  return all;
}

bool Near(double a, double b) {
  if (a == b || (std::isnan(a) && std::isnan(b))) return true;
  const double d = std::abs(a - b);
  return d <= 1e-12 * std::max(std::abs(a), std::abs(b)) || d < 1e-9;
}

struct Tally {
  std::size_t files = 0;
  std::size_t messages = 0;
  std::size_t frames = 0;
  std::size_t compared = 0;
  std::size_t agreed = 0;
  std::size_t null_overhang = 0;
  std::size_t null_sna = 0;
  std::size_t null_mux = 0;
  std::size_t canmatrix_lacks_signal = 0;
  std::size_t canmatrix_lacks_message = 0;
  std::size_t canmatrix_padded = 0;
};

std::int64_t SignedRaw(std::uint64_t bits, std::uint32_t length) {
  if (length >= 64) return static_cast<std::int64_t>(bits);
  const std::uint64_t sign_bit = std::uint64_t{1} << (length - 1);
  return static_cast<std::int64_t>((bits ^ sign_bit) - sign_bit);
}

/// One DBC and the random frames written for it, exactly as long as each message is declared.
struct Case {
  fs::path path;
  Dbc dbc;
  std::vector<std::pair<std::size_t, std::vector<std::uint8_t>>> frames;
  fs::path frames_path;
};

Case MakeCase(const fs::path& path, std::uint64_t seed, int frames_per_message, int n) {
  Case c{path, ParseDbc(test::ReadFile(path), path.string()), {}, {}};
  const DbcCodec codec(c.dbc);
  std::mt19937_64 rng(seed);
  c.frames_path = fs::temp_directory_path() / ("pumptherm_canmatrix_" + std::to_string(getpid()) +
                                               "_" + std::to_string(n) + ".txt");
  std::ofstream f(c.frames_path);
  for (std::size_t mi = 0; mi < c.dbc.messages.size(); ++mi) {
    for (int k = 0; k < frames_per_message; ++k) {
      std::vector<std::uint8_t> data(codec.message(mi).min_bytes());
      for (auto& b : data) b = static_cast<std::uint8_t>(rng());
      f << std::hex << c.dbc.messages[mi].id << std::dec << ' '
        << (c.dbc.messages[mi].extended ? 1 : 0) << ' ';
      for (auto b : data) f << "0123456789ABCDEF"[b >> 4] << "0123456789ABCDEF"[b & 15];
      f << '\n';
      c.frames.emplace_back(mi, std::move(data));
    }
  }
  return c;
}

void Compare(const Case& test_case, const Theirs& theirs, Tally& tally) {
  SCOPED_TRACE(test_case.path.string());
  const Dbc& dbc = test_case.dbc;
  const DbcCodec codec(dbc);
  ++tally.files;
  tally.messages += dbc.messages.size();
  tally.frames += test_case.frames.size();
  tally.canmatrix_lacks_message += theirs.missing;
  tally.canmatrix_padded += theirs.padded;
  for (std::size_t fi = 0; fi < test_case.frames.size(); ++fi) {
    const auto& [mi, data] = test_case.frames[fi];
    const DbcMessage& m = dbc.messages[mi];
    const MessageCodec& mc = codec.message(mi);
    std::vector<double> ours(mc.signal_count());
    ASSERT_EQ(mc.Decode(data, ours), CodecStatus::kOk);
    for (std::size_t si = 0; si < m.signals.size(); ++si) {
      const DbcSignal& s = m.signals[si];
      const auto it = theirs.values.find({static_cast<int>(fi), s.name});
      const bool overhangs = SignalEndByte(s) > m.size_bytes;
      if (it == theirs.values.end()) {
        // Not selected by the multiplexer on both sides, or a signal canmatrix could not read.
        if (!std::isnan(ours[si])) ++tally.canmatrix_lacks_signal;
        continue;
      }
      const TheirValue& c = it->second;
      if (std::isnan(ours[si]) && !std::isnan(c.physical)) {
        const std::uint64_t bits = mc.RawBits(data, si);
        const std::uint64_t mask = s.length_bits >= 64 ? ~0ull : (1ull << s.length_bits) - 1;
        if (overhangs) {
          ++tally.null_overhang;
        } else if (s.not_available_raw &&
                   bits == (static_cast<std::uint64_t>(*s.not_available_raw) & mask)) {
          ++tally.null_sna;
        } else {
          EXPECT_FALSE(mc.IsPresent(data, si)) << m.name << "." << s.name << " frame " << fi
                                               << ": ours null, canmatrix " << c.physical;
          ++tally.null_mux;
        }
        continue;
      }
      ++tally.compared;
      bool ok = Near(ours[si], c.physical);
      if (s.value_type == SignalValueType::kInteger) {
        const std::uint64_t bits = mc.RawBits(data, si);
        const double our_raw = s.is_signed ? static_cast<double>(SignedRaw(bits, s.length_bits))
                                           : static_cast<double>(bits);
        ok = ok && our_raw == c.raw;
        EXPECT_EQ(our_raw, c.raw) << m.name << "." << s.name << " frame " << fi;
      }
      EXPECT_TRUE(Near(ours[si], c.physical))
          << m.name << "." << s.name << " frame " << fi << ": ours " << ours[si] << " canmatrix "
          << c.physical;
      if (ok) ++tally.agreed;
    }
  }
}

TEST(CodecCanmatrixTest, DecodesLikeCanmatrixOnEveryDbc) {
  const std::string why = CanmatrixUnavailable();
  if (!why.empty()) {
    if (InCi()) FAIL() << "CI=true and the cross-check cannot run: " << why;
    GTEST_SKIP() << why;
  }
  std::vector<fs::path> files = test::RealDbcFiles();
  const std::size_t real = files.size();
  if (files.empty()) {
    if (InCi()) FAIL() << "CI=true and no shared DBC files under " << test::SharedDbcDir();
    std::cout << "no shared DBC files under " << test::SharedDbcDir() << ": shipped DBC only\n";
  }
  files.push_back(test::PumpthermDbc());
  files.push_back(test::SourceDir() / "tests" / "protocol" / "candied" / "features.dbc");
  std::vector<Case> cases;
  std::vector<std::pair<fs::path, fs::path>> pairs;
  for (std::size_t i = 0; i < files.size(); ++i) {
    cases.push_back(MakeCase(files[i], 200 + i, 4, static_cast<int>(i)));
    pairs.emplace_back(cases.back().path, cases.back().frames_path);
  }
  const std::vector<Theirs> theirs = RunCanmatrix(pairs);
  Tally tally;
  for (std::size_t i = 0; i < cases.size(); ++i) {
    fs::remove(cases[i].frames_path);
    Compare(cases[i], theirs[i], tally);
  }
  std::cout << "files " << tally.files << " (" << real << " shared), messages " << tally.messages
            << ", frames " << tally.frames << ": " << tally.agreed << " of " << tally.compared
            << " values agree with canmatrix; ours null where canmatrix has a number: "
            << tally.null_overhang << " overhanging, " << tally.null_sna << " GenSigSNA, "
            << tally.null_mux << " not selected by the multiplexer; canmatrix lacks "
            << tally.canmatrix_lacks_signal << " values we decode and "
            << tally.canmatrix_lacks_message << " frames' messages; " << tally.canmatrix_padded
            << " frames canmatrix could decode only padded to 64 bytes\n";
  EXPECT_GT(tally.compared, 0u);
  EXPECT_EQ(tally.agreed, tally.compared);
}

// Long names (SystemMessageLongSymbol, SystemSignalLongSymbol) are the names canmatrix shows:
// every message and every signal we decode in a frame has the name canmatrix gives it.
TEST(CodecCanmatrixTest, LongNamesAreTheNamesCanmatrixShows) {
  const std::string why = CanmatrixUnavailable();
  if (!why.empty()) {
    if (InCi()) FAIL() << "CI=true and the cross-check cannot run: " << why;
    GTEST_SKIP() << why;
  }
  const Case c =
      MakeCase(test::SourceDir() / "tests" / "protocol" / "dbc" / "long_names.dbc", 7, 4, 900);
  const std::vector<Theirs> theirs = RunCanmatrix({{c.path, c.frames_path}});
  fs::remove(c.frames_path);
  ASSERT_EQ(theirs.size(), 1u);
  const DbcCodec codec(c.dbc);
  std::size_t names = 0;
  for (std::size_t fi = 0; fi < c.frames.size(); ++fi) {
    const auto& [mi, data] = c.frames[fi];
    const DbcMessage& m = c.dbc.messages[mi];
    EXPECT_EQ(theirs[0].message_names.at(static_cast<int>(fi)), m.name);
    std::vector<double> ours(codec.message(mi).signal_count());
    ASSERT_EQ(codec.message(mi).Decode(data, ours), CodecStatus::kOk);
    for (std::size_t si = 0; si < m.signals.size(); ++si) {
      // A long name that would repeat another signal's keeps its short one here; canmatrix
      // gives both signals the one name.
      if (m.signals[si].name == "WouldRepeatTaken" || !codec.message(mi).IsPresent(data, si))
        continue;
      EXPECT_TRUE(theirs[0].values.contains({static_cast<int>(fi), m.signals[si].name}))
          << m.name << "." << m.signals[si].name << " frame " << fi;
      ++names;
    }
  }
  EXPECT_GT(names, 20u);
  std::cout << names << " signal values under the same long names as canmatrix's\n";
}

}  // namespace
}  // namespace pumptherm::protocol
