#pragma once
/// The safety state: what must never be lost or rolled back across a crash, kept apart from the
/// estimator state (docs/daemon.md, "State across restarts"): every pump's latched trips and the
/// last accepted clear counter of each operator key. It is small, written atomically
/// (WriteFileAtomically: temporary, fsync, rename, fsync of the directory) before a clear acts
/// and at once when a trip latches, and carries a checksum so damage is found, not guessed.

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace pumptherm::daemon {

/// The file name of the safety state in the state directory.
inline constexpr const char* kSafetyStateFile = "safety.toml";

struct SafetyState {
  struct Latch {
    std::string node;         ///< alarm node: a model node, "sensor", "winding_resistance", ...
    double value_degC = 0.0;  ///< the value that raised it (0 where none does)
  };
  /// Pump -> its latched trips. Every configured pump is listed, with none when none is latched,
  /// so a pump missing from a file is one configured since it was written.
  std::map<std::string, std::vector<Latch>> latched;
  /// Pump -> key ID -> the last counter accepted from that key for that pump.
  std::map<std::string, std::map<std::string, std::int64_t>> counters;
  /// No command signed (utime, us since the Unix epoch) at or before this is accepted: the
  /// start time after the counters were lost.
  std::int64_t refused_up_to_us = 0;
};

/// The file's text: TOML with a version, then a last line "# blake2b-256 HEX" over every byte
/// before it.
std::string FormatSafetyState(const SafetyState& s);

/// The safety state in `text` (as FormatSafetyState writes it); nullopt, with what is wrong in
/// `*problem`, for a file that does not end in a checksum that matches, does not parse, has an
/// unknown version, or holds a value of the wrong type. Never throws.
std::optional<SafetyState> ParseSafetyState(std::string_view text, std::string* problem);

/// Whether estimator state text `state_toml` was written by a version before the safety state
/// had a file of its own (it holds a [clear_auth] table): its latched trips are then the
/// safety state (read with it), and a missing safety file is no loss.
bool WrittenBeforeSafetyFile(std::string_view state_toml);

}  // namespace pumptherm::daemon
