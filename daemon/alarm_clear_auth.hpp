#pragma once
/// Authenticated alarm clears over LCM (docs/threat-model.md, docs/lcm.md "Clearing a trip").
///
/// A clear command (pumptherm::alarm_clear_t) carries an HMAC-SHA-512-256 (libsodium's
/// crypto_auth) made with a 32-byte key that only operators can read, over every field of the
/// command. The gateway accepts it only when the code is right, its time is inside a window
/// around the gateway's clock, and its counter is above the last one accepted for that pump
/// (the counters are kept across restarts in the saved state). The gateway answers each
/// command of a configured pump with a pumptherm::alarm_clear_reply_t signed with the same key.

#include <array>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <string_view>

#include "pumptherm/alarm_clear_reply_t.hpp"
#include "pumptherm/alarm_clear_t.hpp"

namespace lcm {
class LCM;
}

namespace toml {
inline namespace v3 {
class table;
}
}  // namespace toml

namespace pumptherm::daemon {

struct DaemonConfig;

/// The clear key: 32 random bytes (crypto_auth_KEYBYTES).
inline constexpr std::size_t kClearKeyBytes = 32;
using ClearKey = std::array<std::uint8_t, kClearKeyBytes>;

/// Name of the systemd credential that carries the key (LoadCredential= in the unit), and
/// what it holds when there was no key file (the unit's SetCredential= fallback).
inline constexpr const char* kClearKeyCredential = "pumptherm-clear-key";
inline constexpr std::string_view kNoClearKeyCredential = "none";

/// What is wrong with the permissions of key file `path`, or "" when nothing is: it must be a
/// regular file that others can neither read nor write and its group cannot write, and it must
/// belong to group `group` (skipped when `group` is empty, and when the file's group cannot be
/// seen because this process runs in a user namespace that does not map it, as under the
/// unit's PrivateUsers=). Never throws.
std::string ClearKeyFileProblem(const std::string& path, const std::string& group);

/// Reads a key file: exactly 32 bytes. Throws std::runtime_error naming `path` (unreadable,
/// wrong size).
ClearKey ReadClearKeyFile(const std::string& path);

/// The key of `config` (alarms.clear_key_file), or nullopt when none is configured. Checks the
/// file's permissions (ClearKeyFileProblem) and reads it, or, when systemd handed it over as
/// credential kClearKeyCredential in `credentials_dir` (non-empty, and the credential not
/// kNoClearKeyCredential), reads that copy. Throws
/// ConfigError "FILE:LINE: key 'alarms.clear_key_file': PROBLEM" for any problem.
std::optional<ClearKey> LoadConfiguredClearKey(const DaemonConfig& config,
                                               const std::string& credentials_dir);

/// $CREDENTIALS_DIRECTORY, or "" outside systemd.
std::string CredentialsDirectory();

/// The authentication code of `m` (every field but `mac`, laid out as docs/lcm.md says).
std::array<std::uint8_t, 32> ClearMac(const ClearKey& key, const pumptherm::alarm_clear_t& m);
std::array<std::uint8_t, 32> ClearReplyMac(const ClearKey& key,
                                           const pumptherm::alarm_clear_reply_t& m);
/// Fills `m.mac`.
void Sign(const ClearKey& key, pumptherm::alarm_clear_t& m);
void Sign(const ClearKey& key, pumptherm::alarm_clear_reply_t& m);
/// True when `m.mac` is right for `key` (compared in constant time).
bool Verify(const ClearKey& key, const pumptherm::alarm_clear_t& m);
bool Verify(const ClearKey& key, const pumptherm::alarm_clear_reply_t& m);

/// What came back for one clear command (SendClear).
struct ClearExchange {
  std::optional<pumptherm::alarm_clear_reply_t> reply;  ///< the answer, signed with the key
  int untrusted_replies = 0;     ///< answers to this counter not signed with the key
  std::string untrusted_reason;  ///< the reason the last of those gave
};

/// The client's side (`pumptherm clear-trip`): signs `m` with `key`, publishes it on
/// <prefix>/<m.pump>/ALARM_CLEAR over `lcm`, and waits up to `timeout_s` (wall clock) for the
/// answer to its counter on <prefix>/<m.pump>/ALARM_CLEAR_REPLY, handling `lcm` meanwhile.
/// Throws std::runtime_error when LCM refuses to publish.
ClearExchange SendClear(lcm::LCM& lcm, const std::string& prefix, const ClearKey& key,
                        pumptherm::alarm_clear_t m, double timeout_s);

/// The gateway's side: the key, the time window and the last accepted counter of each pump.
class ClearAuthenticator {
 public:
  /// `window_s`: how far a command's utime may lie from the gateway's clock, either way.
  explicit ClearAuthenticator(double window_s)
      : window_us_(static_cast<std::int64_t>(window_s * 1e6)) {}

  void SetKey(const ClearKey& key) { key_ = key; }
  bool has_key() const { return key_.has_value(); }

  /// The verdict on command `m` at gateway time `now_us` (us since the Unix epoch), as one of
  /// alarm_clear_reply_t::RESULT_*, with the reason in words in `*reason`. `source_allowed`:
  /// whether m.source is a configured source of the pump. Checked in this order: key, code,
  /// source, window, counter; an accepted command's counter becomes the pump's last one.
  std::int8_t Check(const pumptherm::alarm_clear_t& m, bool source_allowed, std::int64_t now_us,
                    std::string* reason);

  /// The highest counter accepted for `pump` (0 when none).
  std::int64_t last_counter(const std::string& pump) const;

  /// The reply to command `m` with verdict `result`, signed when there is a key.
  pumptherm::alarm_clear_reply_t Reply(const pumptherm::alarm_clear_t& m, std::int8_t result,
                                       const std::string& reason, bool trip_latched,
                                       std::int64_t now_us) const;

  /// Adds table [clear_auth] (its own version) with the counters to saved state `root`.
  void Save(toml::table& root) const;
  /// Takes the counters from saved state `root` (absent in files written before they were
  /// kept: none). A counter never goes down. Returns a warning, or "" when all was well.
  std::string Restore(const toml::table& root);

 private:
  std::optional<ClearKey> key_;
  std::int64_t window_us_;
  std::map<std::string, std::int64_t> last_counter_;
};

}  // namespace pumptherm::daemon
