#include "tools/pumptherm/watch_digest.hpp"

#include <algorithm>
#include <cstring>

namespace pumptherm::tools {

DigestCheck::DigestCheck(const daemon::PublicKey& gateway, std::string prefix)
    : gateway_(gateway), prefix_(std::move(prefix)) {}

bool DigestCheck::OnDigest(const pumptherm::gateway_digest_t& d, std::int64_t now_us) {
  if (!daemon::VerifyDigest(gateway_, prefix_, d)) {
    ++bad_digests_;
    return false;
  }
  for (std::size_t i = 0; i < d.channels.size(); ++i) {
    daemon::MessageHash h{};
    std::memcpy(h.data(), d.hashes.data() + i * h.size(), h.size());
    listed_.emplace(h, d.channels[i]);
    listed_order_.emplace_back(now_us, h, d.channels[i]);
  }
  while (!listed_order_.empty() && now_us - std::get<0>(listed_order_.front()) > kKeepUs) {
    const auto& [t, h, c] = listed_order_.front();
    listed_.erase(listed_.find({h, c}));
    listed_order_.pop_front();
  }
  last_digest_rx_us_ = now_us;
  return true;
}

void DigestCheck::OnMessage(const std::string& channel, const void* data, std::size_t size,
                            std::int64_t now_us) {
  constexpr std::size_t kMaxPerChannel = 256;
  std::deque<Seen>& q = recent_[channel];
  q.push_back({daemon::HashOfMessage(data, size), now_us});
  while (q.size() > kMaxPerChannel || now_us - q.front().rx_us > kKeepUs) q.pop_front();
}

DigestCheck::Verdict DigestCheck::Latest(const std::string& channel) const {
  const auto it = recent_.find(channel);
  if (it == recent_.end() || it->second.empty()) return Verdict::kNone;
  const auto listed = [&](const Seen& s) { return listed_.count({s.hash, channel}) > 0; };
  if (listed(it->second.back())) return Verdict::kSigned;
  // The gateway lists each message in its next digest: one that signed digests received well
  // after it still do not list was not the gateway's.
  const bool forged = std::any_of(it->second.begin(), it->second.end(), [&](const Seen& s) {
    return !listed(s) && last_digest_rx_us_ - s.rx_us > kListedWithinUs;
  });
  return forged ? Verdict::kNotSigned : Verdict::kPending;
}

}  // namespace pumptherm::tools
