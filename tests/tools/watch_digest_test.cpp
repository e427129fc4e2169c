// The gateway's signed digest of what it published, and `pumptherm watch --gateway-key`'s
// verdict from it (docs/threat-model.md, "Readers misled"): the gateway's messages are signed,
// a forged message on a pump's channel and a phantom pump are not, a digest of another key
// counts for nothing.
#include "tools/pumptherm/watch_digest.hpp"

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "daemon/publish_digest.hpp"

namespace pumptherm::tools {
namespace {

using daemon::PublishDigest;
using daemon::Seed;
using daemon::SigningKey;
using V = DigestCheck::Verdict;

constexpr std::int64_t kT0 = 1'763'776'800'000'000;
const std::vector<std::uint8_t> kTemps{1, 2, 3, 4};
const std::vector<std::uint8_t> kAlarm{9, 8, 7};
const std::vector<std::uint8_t> kForged{1, 2, 3, 5};

TEST(PublishDigest, IsSignedForItsGatewayAndPrefix) {
  const SigningKey gw(Seed{4, 4}), other(Seed{5, 5});
  PublishDigest d;
  d.Add("P/pump1/TEMPS", kTemps);
  d.Add("P/pump1/ALARM", kAlarm);
  auto digest = d.Take("hall1", "P", kT0, gw);
  EXPECT_EQ(digest.num_messages, 2);
  EXPECT_EQ(digest.seq, 1);
  EXPECT_EQ(digest.hashes.size(), 32U);
  EXPECT_TRUE(daemon::VerifyDigest(gw.public_key(), "P", digest));
  EXPECT_FALSE(daemon::VerifyDigest(other.public_key(), "P", digest));
  EXPECT_FALSE(daemon::VerifyDigest(gw.public_key(), "Q", digest));
  auto tampered = digest;
  tampered.hashes[0] ^= 1;
  EXPECT_FALSE(daemon::VerifyDigest(gw.public_key(), "P", tampered));
  tampered = digest;
  tampered.channels.pop_back();  // inconsistent: refused before the signature
  EXPECT_FALSE(daemon::VerifyDigest(gw.public_key(), "P", tampered));
  // The next one starts empty and says so, signed.
  const auto empty = d.Take("hall1", "P", kT0 + 1'000'000, gw);
  EXPECT_EQ(empty.num_messages, 0);
  EXPECT_EQ(empty.seq, 2);
  EXPECT_TRUE(daemon::VerifyDigest(gw.public_key(), "P", empty));
}

TEST(DigestCheck, TellsTheGatewaysMessagesFromAForgersAndAPhantomPump) {
  const SigningKey gw(Seed{4, 4}), forger(Seed{6, 6});
  DigestCheck check(gw.public_key(), "P");
  PublishDigest published;
  // The gateway publishes TEMPS and ALARM of pump1; the watcher receives them, then the digest.
  published.Add("P/pump1/TEMPS", kTemps);
  published.Add("P/pump1/ALARM", kAlarm);
  check.OnMessage("P/pump1/TEMPS", kTemps.data(), kTemps.size(), kT0);
  check.OnMessage("P/pump1/ALARM", kAlarm.data(), kAlarm.size(), kT0);
  EXPECT_EQ(check.Latest("P/pump1/TEMPS"), V::kPending);
  EXPECT_FALSE(check.any_digest());
  EXPECT_TRUE(check.OnDigest(published.Take("hall1", "P", kT0, gw), kT0 + 500'000));
  EXPECT_EQ(check.Latest("P/pump1/TEMPS"), V::kSigned);
  EXPECT_EQ(check.Latest("P/pump1/ALARM"), V::kSigned);
  EXPECT_EQ(check.Latest("P/pump9/TEMPS"), V::kNone);
  // A forger publishes a "normal, 25 degC" TEMPS for pump1 and a phantom pump: pending until
  // the gateway's digests go on without them.
  check.OnMessage("P/pump1/TEMPS", kForged.data(), kForged.size(), kT0 + 600'000);
  check.OnMessage("P/phantom/TEMPS", kForged.data(), kForged.size(), kT0 + 600'000);
  EXPECT_EQ(check.Latest("P/pump1/TEMPS"), V::kPending);
  // The forger's own digest (another key) counts for nothing.
  PublishDigest forged;
  forged.Add("P/pump1/TEMPS", kForged);
  forged.Add("P/phantom/TEMPS", kForged);
  EXPECT_FALSE(check.OnDigest(forged.Take("hall1", "P", kT0, forger), kT0 + 700'000));
  EXPECT_EQ(check.bad_digests(), 1U);
  for (int k = 1; k <= 5; ++k) {
    EXPECT_TRUE(
        check.OnDigest(published.Take("hall1", "P", kT0, gw), kT0 + 700'000 + k * 1'000'000));
  }
  EXPECT_EQ(check.Latest("P/pump1/TEMPS"), V::kNotSigned);
  EXPECT_EQ(check.Latest("P/phantom/TEMPS"), V::kNotSigned);
  EXPECT_EQ(check.Latest("P/pump1/ALARM"), V::kSigned);
  // The gateway's next TEMPS is signed again.
  published.Add("P/pump1/TEMPS", kTemps);
  check.OnMessage("P/pump1/TEMPS", kTemps.data(), kTemps.size(), kT0 + 6'000'000);
  EXPECT_TRUE(check.OnDigest(published.Take("hall1", "P", kT0, gw), kT0 + 6'500'000));
  EXPECT_EQ(check.Latest("P/pump1/TEMPS"), V::kSigned);
}

}  // namespace
}  // namespace pumptherm::tools
