#pragma once
/// Signed alarm clears over LCM (docs/threat-model.md, docs/lcm.md "Clearing a trip").
///
/// An operator signs a clear command (pumptherm::alarm_clear_t) with an Ed25519 key of their
/// own; the gateway holds only the operators' public keys, with names, so the source it logs is
/// the signer's proven name. The signed bytes cover the gateway's name and LCM channel prefix,
/// the pump, the node, the key ID, the comment, the time and a counter, so a command acts on
/// one gateway, once. Besides the signature a command carries a tag made with the key that the
/// operator's and the gateway's key pairs share (crypto_kx): checking it costs about a
/// thousandth of a signature check, so a flood of forged commands is refused cheaply. The
/// gateway answers (pumptherm::alarm_clear_reply_t, signed with its own key) only commands whose
/// signature holds.
///
/// The shared key of the earlier scheme (one 32-byte HMAC key for every operator, the source a
/// claim) is kept as a migration path, off unless alarms.clear_allow_shared_key is set.

#include <array>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "daemon/clear_keys.hpp"
#include "pumptherm/alarm_clear_reply_t.hpp"
#include "pumptherm/alarm_clear_t.hpp"

namespace lcm {
class LCM;
}

namespace pumptherm::daemon {

struct DaemonConfig;

/// The shared key of the earlier scheme: 32 random bytes (crypto_auth_KEYBYTES).
inline constexpr std::size_t kClearKeyBytes = 32;
using ClearKey = std::array<std::uint8_t, kClearKeyBytes>;

/// Names of the systemd credentials (LoadCredential= in the unit) that carry the gateway's key
/// and the shared key, and what they hold when there was no file (the unit's SetCredential=).
inline constexpr const char* kGatewayKeyCredential = "pumptherm-gateway-key";
inline constexpr const char* kClearKeyCredential = "pumptherm-clear-key";
inline constexpr std::string_view kNoCredential = "none";

/// key_id of a command signed with the shared key: this prefix and the claimed source.
inline constexpr std::string_view kSharedKeyIdPrefix = "shared:";

/// What is wrong with the permissions of shared key file `path`, or "" when nothing is: a
/// regular file that others can neither read nor write and its group cannot write, belonging to
/// group `group` (skipped when empty, or when the group is not mapped into this process's user
/// namespace, as under the unit's PrivateUsers=). Never throws.
std::string ClearKeyFileProblem(const std::string& path, const std::string& group);

/// Reads a shared key file: exactly 32 bytes, not all zero. Throws std::runtime_error naming
/// `path`.
ClearKey ReadClearKeyFile(const std::string& path);

/// The shared key of `config` when alarms.clear_allow_shared_key is set (else nullopt): its
/// permissions checked (ClearKeyFileProblem), read from systemd's copy in `credentials_dir`
/// when there is one. Throws ConfigError "FILE:LINE: key 'alarms.clear_key_file': PROBLEM".
std::optional<ClearKey> LoadConfiguredClearKey(const DaemonConfig& config,
                                               const std::string& credentials_dir);

/// The gateway's signing key (gateway.signing_key_file), or nullopt when none is configured:
/// the file's permissions checked (SecretKeyFileProblem, root or this user may own it), read
/// from systemd's copy (credential kGatewayKeyCredential) in `credentials_dir` when there is
/// one. Throws ConfigError "FILE:LINE: key 'gateway.signing_key_file': PROBLEM".
std::optional<SigningKey> LoadConfiguredGatewayKey(const DaemonConfig& config,
                                                   const std::string& credentials_dir);

/// $CREDENTIALS_DIRECTORY, or "" outside systemd.
std::string CredentialsDirectory();

/// The bytes a command's tag and signature cover (docs/lcm.md, "Signed bytes"), with the
/// channel prefix it is sent under; the tag and signature fields are not part of them.
std::vector<std::uint8_t> SignedBytes(const pumptherm::alarm_clear_t& m, std::string_view prefix);
/// The bytes a reply's signature covers.
std::vector<std::uint8_t> SignedBytes(const pumptherm::alarm_clear_reply_t& m,
                                      std::string_view prefix);

/// The operator's side: sets m.key_id to `op`'s, then the tag (with the key `op` shares with
/// `gateway`) and the signature. m.gateway names the gateway (its gateway.name).
void SignCommand(const SigningKey& op, const PublicKey& gateway, std::string_view prefix,
                 pumptherm::alarm_clear_t& m);
/// The earlier scheme: key_id "shared:SOURCE", the tag an HMAC with `key`, no signature.
void SignCommandShared(const ClearKey& key, const std::string& source, std::string_view prefix,
                       pumptherm::alarm_clear_t& m);
/// The gateway's side of a reply.
void SignReply(const SigningKey& gateway, std::string_view prefix,
               pumptherm::alarm_clear_reply_t& r);
bool VerifyReply(const PublicKey& gateway, std::string_view prefix,
                 const pumptherm::alarm_clear_reply_t& r);

/// What came back for one clear command (SendClear).
struct ClearExchange {
  std::optional<pumptherm::alarm_clear_reply_t> reply;  ///< the answer, signed by the gateway
  int untrusted_replies = 0;     ///< answers to this command whose signature does not hold
  std::string untrusted_reason;  ///< the reason the last of those gave
};

/// The client's side (`pumptherm clear-trip`): publishes the signed command `m` on
/// <prefix>/<m.pump>/ALARM_CLEAR over `lcm` and waits up to `timeout_s` (wall clock) for the
/// answer to its key ID and counter on <prefix>/<m.pump>/ALARM_CLEAR_REPLY, trusting only an
/// answer signed with `gateway`. Throws std::runtime_error when LCM refuses to publish.
ClearExchange SendClear(lcm::LCM& lcm, std::string_view prefix, const PublicKey& gateway,
                        const pumptherm::alarm_clear_t& m, double timeout_s);

/// An operator's key as the gateway knows it (alarms.clear_operators).
struct ClearOperator {
  std::string name;  ///< who holds it: logged as the source of what it signs
  PublicKey public_key{};
  bool revoked = false;  ///< kept listed so that its use is logged as such
};

/// What ClearAuthenticator::Check found, in the order it checks.
enum class ClearCheck : std::uint8_t {
  kNoGatewayKey,   ///< no gateway.signing_key_file: LCM clears are off
  kOtherGateway,   ///< m.gateway is another gateway's name
  kUnknownKey,     ///< key_id not configured (or a shared-key command with that scheme off)
  kRevokedKey,     ///< the operator's key is revoked
  kBadTag,         ///< no or a wrong tag: forged (the cheap check)
  kReplayed,       ///< counter not above the last accepted from this key for this pump
  kBadSignature,   ///< the tag held, the signature did not
  kOutsideWindow,  ///< signed, but utime too far from the gateway's clock
  kPassed,         ///< signed, fresh, in time: the gateway decides on the node and saves
};

struct ClearCheckResult {
  ClearCheck check = ClearCheck::kNoGatewayKey;
  /// Who signed it: the operator's name and key ID when the key is known, else what the command
  /// claims ("key 0123abcd... (unknown)").
  std::string source;
  std::string reason;  ///< the verdict in words (logged)
  /// The signature (or the shared key's tag) held: the command deserves an answer.
  bool authenticated() const {
    return check == ClearCheck::kOutsideWindow || check == ClearCheck::kPassed;
  }
  /// A command without a valid tag or signature (counted in clears_unauthenticated).
  bool forged() const {
    return check == ClearCheck::kUnknownKey || check == ClearCheck::kBadTag ||
           check == ClearCheck::kBadSignature;
  }
};

/// The gateway's side: its key, the operators' keys, the time window and the last accepted
/// counter of each key for each pump.
class ClearAuthenticator {
 public:
  /// `gateway`, `prefix`: the gateway's name and LCM channel prefix (the signatures cover both);
  /// `window_s`: how far a command's utime may lie from the gateway's clock, either way.
  ClearAuthenticator(std::string gateway, std::string prefix, double window_s);

  /// The gateway's own key: signs replies; with an operator's public key it gives their tag key.
  void SetGatewayKey(const SigningKey& key);
  bool has_gateway_key() const { return gateway_key_.has_value(); }
  /// The gateway's key (nullptr: none), which also signs the digest of what it publishes.
  const SigningKey* gateway_key() const { return gateway_key_ ? &*gateway_key_ : nullptr; }
  /// Adds an operator's key; call after SetGatewayKey (the tag key needs it). Throws
  /// std::invalid_argument for a key that cannot be used, or one listed twice.
  void AddOperator(const ClearOperator& op);
  /// The shared key of the earlier scheme and the sources it may claim (migration).
  void SetSharedKey(const ClearKey& key, std::vector<std::string> sources);

  /// The verdict on command `m` at gateway time `now_us` (us since the Unix epoch). Cheap
  /// checks first: no signature is checked unless the tag holds and the counter is new. Takes
  /// nothing: Take() does, once the clear is durable.
  ClearCheckResult Check(const pumptherm::alarm_clear_t& m, std::int64_t now_us) const;
  /// Makes m.counter the last accepted of its key for its pump.
  void Take(const pumptherm::alarm_clear_t& m);

  /// The last counter accepted from `key_id` for `pump` (0 when none).
  std::int64_t last_counter(const std::string& pump, const std::string& key_id) const;
  /// Every last counter: pump -> key ID -> counter.
  using Counters = std::map<std::string, std::map<std::string, std::int64_t>>;
  const Counters& counters() const { return counters_; }
  /// Takes `counters` where they are higher (a counter never goes down).
  void MergeCounters(const Counters& counters);
  /// No command signed (utime) at or before `utime` is accepted from any key: after the
  /// counters were lost, the start time, so a command recorded before cannot replay. Never goes
  /// down.
  void RefuseSignedUpTo(std::int64_t utime);
  std::int64_t refused_up_to_us() const { return refused_up_to_us_; }

  /// The reply to command `m` with verdict `result`, signed with the gateway's key (which a
  /// command that passed Check implies).
  pumptherm::alarm_clear_reply_t Reply(const pumptherm::alarm_clear_t& m, std::int8_t result,
                                       const std::string& reason, bool trip_latched,
                                       std::int64_t now_us) const;

  const std::string& gateway() const { return gateway_; }
  const std::string& prefix() const { return prefix_; }

 private:
  struct KnownKey {
    ClearOperator op;
    TagKey tag_key;
  };
  ClearCheckResult CheckShared(const pumptherm::alarm_clear_t& m,
                               const std::vector<std::uint8_t>& bytes, std::int64_t now_us) const;
  /// The counter and window checks every scheme shares; `result` keeps its source.
  bool Fresh(const pumptherm::alarm_clear_t& m, ClearCheckResult& result) const;
  bool InWindow(const pumptherm::alarm_clear_t& m, std::int64_t now_us,
                ClearCheckResult& result) const;

  std::string gateway_, prefix_;
  std::int64_t window_us_;
  std::optional<SigningKey> gateway_key_;
  std::map<std::string, KnownKey> keys_;  ///< by key ID
  std::optional<ClearKey> shared_key_;
  std::vector<std::string> shared_sources_;
  Counters counters_;
  std::int64_t refused_up_to_us_ = 0;
};

}  // namespace pumptherm::daemon
