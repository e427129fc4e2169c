#pragma once
/// The gateway's signed digest of what it published on LCM (docs/threat-model.md, "Readers
/// misled"): every message's channel and a 16-byte BLAKE2b hash of its bytes, collected between
/// digests and signed with the gateway's key, so that a reader holding the gateway's public key
/// can tell the gateway's TEMPS and ALARM from a forger's. Shared by the daemon (which makes
/// the digests) and `pumptherm watch` (which checks them).

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "daemon/clear_keys.hpp"
#include "pumptherm/gateway_digest_t.hpp"

namespace pumptherm::daemon {

/// The first 16 bytes of BLAKE2b of a message's encoded bytes.
using MessageHash = std::array<std::uint8_t, 16>;
MessageHash HashOfMessage(const void* data, std::size_t size);

/// The bytes a digest's signature covers (docs/lcm.md, "Signed bytes"), with its channel prefix.
std::vector<std::uint8_t> SignedBytes(const pumptherm::gateway_digest_t& d,
                                      std::string_view prefix);
/// Whether `d` is signed by `gateway` for `prefix` and consistent (as many hashes as channels).
bool VerifyDigest(const PublicKey& gateway, std::string_view prefix,
                  const pumptherm::gateway_digest_t& d);

/// The messages published since the last digest.
class PublishDigest {
 public:
  /// Messages listed per digest at most; more are counted in `left_out`.
  static constexpr std::size_t kMaxMessages = 1024;

  /// A message published on `channel`.
  void Add(const std::string& channel, const std::vector<std::uint8_t>& bytes);
  /// The digest of what was added since the last Take, signed with `key` for `gateway` and
  /// `prefix` at `utime`; starts the next one. Nothing added: an empty digest (it still says
  /// the gateway is there and published nothing).
  pumptherm::gateway_digest_t Take(const std::string& gateway, std::string_view prefix,
                                   std::int64_t utime, const SigningKey& key);
  /// Whether a message was added since the last Take.
  bool Pending() const { return !channels_.empty() || left_out_ > 0; }

 private:
  std::vector<std::string> channels_;
  std::vector<MessageHash> hashes_;
  std::int32_t left_out_ = 0;
  std::int64_t seq_ = 0;
};

}  // namespace pumptherm::daemon
