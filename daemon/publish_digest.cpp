#include "daemon/publish_digest.hpp"

#include <sodium.h>

#include <cstring>

namespace pumptherm::daemon {
namespace {

void PutInt(std::vector<std::uint8_t>& out, std::int64_t v) {
  const auto u = static_cast<std::uint64_t>(v);
  for (int shift = 56; shift >= 0; shift -= 8) out.push_back(static_cast<std::uint8_t>(u >> shift));
}

void PutText(std::vector<std::uint8_t>& out, std::string_view s) {
  const auto n = static_cast<std::uint32_t>(s.size());
  for (int shift = 24; shift >= 0; shift -= 8) out.push_back(static_cast<std::uint8_t>(n >> shift));
  out.insert(out.end(), s.begin(), s.end());
}

}  // namespace

MessageHash HashOfMessage(const void* data, std::size_t size) {
  static const int init = sodium_init();  // libsodium's rule: before any other call
  (void)init;
  MessageHash h{};
  crypto_generichash(h.data(), h.size(), static_cast<const unsigned char*>(data), size, nullptr, 0);
  return h;
}

std::vector<std::uint8_t> SignedBytes(const pumptherm::gateway_digest_t& d,
                                      std::string_view prefix) {
  // The layout of the clear commands' (docs/lcm.md, "Signed bytes"), under its own domain.
  constexpr std::string_view kDomain = "pumptherm.gateway_digest_t.1";
  std::vector<std::uint8_t> out(kDomain.begin(), kDomain.end());
  out.push_back(0);
  PutText(out, prefix);
  PutText(out, d.gateway);
  PutInt(out, d.utime);
  PutInt(out, d.seq);
  PutInt(out, d.num_messages);
  for (const std::string& c : d.channels) PutText(out, c);
  PutText(out, std::string_view(reinterpret_cast<const char*>(d.hashes.data()), d.hashes.size()));
  PutInt(out, d.left_out);
  return out;
}

bool VerifyDigest(const PublicKey& gateway, std::string_view prefix,
                  const pumptherm::gateway_digest_t& d) {
  if (d.num_messages < 0 || d.channels.size() != static_cast<std::size_t>(d.num_messages) ||
      d.hashes.size() != d.channels.size() * sizeof(MessageHash)) {
    return false;
  }
  return VerifySignature(gateway, SignedBytes(d, prefix), d.signature);
}

void PublishDigest::Add(const std::string& channel, const std::vector<std::uint8_t>& bytes) {
  if (channels_.size() >= kMaxMessages) {
    ++left_out_;
    return;
  }
  channels_.push_back(channel);
  hashes_.push_back(HashOfMessage(bytes.data(), bytes.size()));
}

pumptherm::gateway_digest_t PublishDigest::Take(const std::string& gateway, std::string_view prefix,
                                                std::int64_t utime, const SigningKey& key) {
  pumptherm::gateway_digest_t d;
  d.utime = utime;
  d.gateway = gateway;
  d.seq = ++seq_;
  d.num_messages = static_cast<std::int32_t>(channels_.size());
  d.channels = std::move(channels_);
  d.num_hash_bytes = static_cast<std::int32_t>(hashes_.size() * sizeof(MessageHash));
  d.hashes.reserve(static_cast<std::size_t>(d.num_hash_bytes));
  for (const MessageHash& h : hashes_) d.hashes.insert(d.hashes.end(), h.begin(), h.end());
  d.left_out = left_out_;
  const Signature sig = key.Sign(SignedBytes(d, prefix));
  std::memcpy(d.signature, sig.data(), sig.size());
  channels_.clear();
  hashes_.clear();
  left_out_ = 0;
  return d;
}

}  // namespace pumptherm::daemon
