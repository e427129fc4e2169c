#pragma once
/// `pumptherm watch --gateway-key`: which TEMPS and ALARM messages the gateway vouches for, from
/// its signed digests (daemon/publish_digest.hpp; docs/threat-model.md, "Readers misled"). A
/// message listed in a digest signed by the gateway's key is the gateway's; one that no digest
/// lists while later digests arrive is someone else's. No I/O: the command feeds messages in.

#include <cstdint>
#include <deque>
#include <map>
#include <set>
#include <string>
#include <tuple>

#include "daemon/publish_digest.hpp"

namespace pumptherm::tools {

class DigestCheck {
 public:
  /// `gateway`: the gateway's public key; `prefix`: its channel prefix.
  DigestCheck(const daemon::PublicKey& gateway, std::string prefix);

  /// A digest received at `now_us` (the watcher's clock, us): its hashes are kept for a while
  /// when its signature holds. Returns whether it did.
  bool OnDigest(const pumptherm::gateway_digest_t& d, std::int64_t now_us);
  /// A message received on `channel` at `now_us`: its bytes' hash becomes that channel's latest.
  void OnMessage(const std::string& channel, const void* data, std::size_t size,
                 std::int64_t now_us);

  enum class Verdict {
    kNone,     ///< nothing received on the channel yet
    kSigned,   ///< the latest message is listed in a signed digest
    kPending,  ///< not listed yet, and no digest came long enough after it to have listed it
    /// The latest message is not listed, and the channel carried a message in the last 30 s
    /// that signed digests received well after it do not list: someone else publishes there.
    kNotSigned,
  };
  /// The verdict on the latest message received on `channel`.
  Verdict Latest(const std::string& channel) const;
  /// Whether a signed digest has come at all.
  bool any_digest() const { return last_digest_rx_us_ >= 0; }

  /// Digests whose signature did not hold (a forger's, or another gateway's).
  std::uint64_t bad_digests() const { return bad_digests_; }

  /// How long a hash from a digest is kept, and how long after a message a digest that does not
  /// list it makes it "not signed" (the gateway lists it in its next digest, lcm.period_s on).
  static constexpr std::int64_t kKeepUs = 30'000'000;
  static constexpr std::int64_t kListedWithinUs = 3'000'000;

 private:
  daemon::PublicKey gateway_;
  std::string prefix_;
  struct Seen {
    daemon::MessageHash hash;
    std::int64_t rx_us;
  };
  std::map<std::string, std::deque<Seen>> recent_;  ///< per channel, the last kKeepUs
  std::multiset<std::pair<daemon::MessageHash, std::string>> listed_;
  std::deque<std::tuple<std::int64_t, daemon::MessageHash, std::string>> listed_order_;
  std::int64_t last_digest_rx_us_ = -1;
  std::uint64_t bad_digests_ = 0;
};

}  // namespace pumptherm::tools
