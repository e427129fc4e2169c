// Signed LCM alarm clears (docs/threat-model.md): a latched trip clears only with a command
// signed by a listed operator key for this gateway and prefix, inside the time window, with a
// new counter, for a node that is latched; forged, replayed, revoked, cross-gateway commands are
// refused, counted and not answered; the clear is durable before it acts; the refusals' journal
// lines carry structured fields, escape what came from outside and are summarised per source.
#include "daemon/alarm_clear_auth.hpp"

#include <grp.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <toml++/toml.h>
#include <unistd.h>

#include <cstdio>
#include <lcm/lcm-cpp.hpp>
#include <stdexcept>
#include <string>

#include "daemon/config.hpp"
#include "daemon/gateway.hpp"
#include "daemon/log.hpp"
#include "daemon/state_store.hpp"
#include "protocol/lcm/channels.hpp"
#include "pumptherm/alarm_clear_reply_t.hpp"
#include "tests/common/test_temp_dir.hpp"

namespace pumptherm::daemon {
namespace {

using Reply = pumptherm::alarm_clear_reply_t;
constexpr std::int64_t kNowUs = 1'763'776'803'000'000;
constexpr const char* kPrefix = "PUMPTHERM";

Seed SeedOf(std::uint8_t first) {
  Seed s{};
  for (std::size_t i = 0; i < s.size(); ++i) s[i] = static_cast<std::uint8_t>(first + i);
  return s;
}
SigningKey KeyOf(std::uint8_t first) { return SigningKey(SeedOf(first)); }

std::string Hex(const std::uint8_t* p, std::size_t n) {
  std::string out;
  char b[3];
  for (std::size_t i = 0; i < n; ++i) {
    std::snprintf(b, sizeof b, "%02x", p[i]);
    out += b;
  }
  return out;
}

/// A command for pump tmp1 of gateway "pumptherm", unsigned.
pumptherm::alarm_clear_t Command(std::int64_t utime, std::int64_t counter,
                                 const std::string& node = "") {
  pumptherm::alarm_clear_t m;
  m.utime = utime;
  m.gateway = "pumptherm";
  m.pump = "tmp1";
  m.node = node;
  m.key_id = "";
  m.comment = "checked";
  m.counter = counter;
  std::fill(std::begin(m.tag), std::end(m.tag), std::uint8_t{0});
  std::fill(std::begin(m.signature), std::end(m.signature), std::uint8_t{0});
  return m;
}

// The signed bytes of docs/lcm.md ("Signed bytes"), written out by hand, and the signature an
// independent Ed25519 gives over them: python3-cryptography 48's
// Ed25519PrivateKey.from_private_bytes(bytes(range(1, 33))).sign(layout) (Ed25519 signatures
// are deterministic, RFC 8032).
TEST(ClearAuth, SignedBytesFollowTheDocumentedLayout) {
  pumptherm::alarm_clear_t m = Command(kNowUs, kNowUs + 17, "winding");
  m.key_id = "00112233445566aa";
  m.comment = "ok";
  auto text = [](const std::string& s) {
    char len[9];
    std::snprintf(len, sizeof len, "%08zx", s.size());
    std::string hex = len;
    for (unsigned char c : s) {
      char b[3];
      std::snprintf(b, sizeof b, "%02x", c);
      hex += b;
    }
    return hex;
  };
  const std::string want =
      Hex(reinterpret_cast<const std::uint8_t*>("pumptherm.alarm_clear_t.2"), 25) + "00" +
      text(kPrefix) + text("pumptherm") + text("tmp1") + text("winding") +
      text("00112233445566aa") + text("ok") + "0006442549ce4ec0" + "0006442549ce4ed1";
  const auto bytes = SignedBytes(m, kPrefix);
  EXPECT_EQ(Hex(bytes.data(), bytes.size()), want);
  const Signature sig = KeyOf(1).Sign(bytes);
  EXPECT_EQ(Hex(sig.data(), sig.size()),
            "0e87a21202ca9801679123b05244c531e585e0b24faadf1694e8f58197b9c1a0"
            "cbff0b957530d0bf2750a91da7a60b7ab2a2cc4e0794e1cae3bc9ad290d10d02");
}

TEST(ClearAuth, EveryFieldAndThePrefixAreCovered) {
  const SigningKey op = KeyOf(1), gw = KeyOf(100);
  pumptherm::alarm_clear_t m = Command(kNowUs, kNowUs);
  SignCommand(op, gw.public_key(), kPrefix, m);
  ClearAuthenticator a("pumptherm", kPrefix, 30.0);
  a.SetGatewayKey(gw);
  a.AddOperator({"alice", op.public_key(), false});
  EXPECT_EQ(a.Check(m, kNowUs).check, ClearCheck::kPassed);
  for (int field = 0; field < 7; ++field) {
    pumptherm::alarm_clear_t t = m;
    switch (field) {
      case 0:
        ++t.utime;
        break;
      case 1:
        t.pump = "tmp2";
        break;
      case 2:
        t.node = "winding";
        break;
      case 3:
        t.comment += ".";
        break;
      case 4:
        ++t.counter;
        break;
      case 5:
        t.tag[3] ^= 1;
        break;
      default:
        t.signature[3] ^= 1;
        break;
    }
    const ClearCheck c = a.Check(t, kNowUs).check;
    EXPECT_TRUE(c == ClearCheck::kBadTag || c == ClearCheck::kBadSignature) << "field " << field;
  }
  // Another prefix (a second gateway of the same name on another prefix).
  ClearAuthenticator other_prefix("pumptherm", "HALL2", 30.0);
  other_prefix.SetGatewayKey(gw);
  other_prefix.AddOperator({"alice", op.public_key(), false});
  EXPECT_EQ(other_prefix.Check(m, kNowUs).check, ClearCheck::kBadTag);
}

TEST(ClearKeys, PublicKeysKeyIdsAndTheSharedTagKey) {
  const SigningKey op = KeyOf(1), gw = KeyOf(100), other = KeyOf(150);
  const std::string text = FormatPublicKey(op.public_key());
  EXPECT_EQ(text.rfind("ed25519:", 0), 0U);
  EXPECT_EQ(text.size(), 8U + 44U);
  std::string problem;
  EXPECT_EQ(ParsePublicKey("  " + text + "\n", &problem), op.public_key());
  EXPECT_FALSE(ParsePublicKey("ssh-ed25519 AAAA", &problem));
  EXPECT_NE(problem.find("ed25519:"), std::string::npos);
  EXPECT_FALSE(ParsePublicKey("ed25519:AAAA", &problem));
  EXPECT_EQ(op.key_id().size(), 16U);
  EXPECT_NE(op.key_id(), gw.key_id());
  // Both ends derive the same tag key; another gateway's differs.
  EXPECT_EQ(op.OperatorTagKey(gw.public_key()), gw.GatewayTagKey(op.public_key()));
  EXPECT_NE(op.OperatorTagKey(other.public_key()), gw.GatewayTagKey(op.public_key()));
  EXPECT_THROW(SigningKey(Seed{}), std::invalid_argument);  // all zero: no key
}

TEST(ClearKeys, KeyFilesAreCheckedForOwnerModeFolderAndZeros) {
  const std::string dir = test_files::TestTempDir("keys");
  ::chmod(dir.c_str(), 0700);
  const std::string path = dir + "/operator.key";
  ::unlink(path.c_str());
  ::unlink(PublicKeyPathOf(path).c_str());
  const SigningKey k = KeyOf(7);
  WriteKeyFiles(path, k, "alice");
  EXPECT_EQ(SecretKeyFileProblem(path, KeyOwner::kCaller), "");
  EXPECT_EQ(ReadSecretKeyFile(path).public_key(), k.public_key());
  EXPECT_EQ(ReadPublicKeyFile(PublicKeyPathOf(path)), k.public_key());
  EXPECT_THROW(WriteKeyFiles(path, KeyOf(8), "bob"), std::system_error);  // never replaced
  EXPECT_EQ(ReadSecretKeyFile(path).public_key(), k.public_key());
  ASSERT_EQ(::chmod(path.c_str(), 0640), 0);
  EXPECT_NE(SecretKeyFileProblem(path, KeyOwner::kCaller).find("open to its group or others"),
            std::string::npos);
  ASSERT_EQ(::chmod(path.c_str(), 0600), 0);
  ASSERT_EQ(::chmod(dir.c_str(), 0777), 0);  // a folder others may write: the key can be swapped
  EXPECT_NE(SecretKeyFileProblem(path, KeyOwner::kCaller).find("which others may write"),
            std::string::npos);
  ASSERT_EQ(::chmod(dir.c_str(), 0700), 0);
  if (::geteuid() == 0) {  // only root can give a file away
    ASSERT_EQ(::chown(path.c_str(), 65534, 65534), 0);
    EXPECT_NE(SecretKeyFileProblem(path, KeyOwner::kCaller).find("belongs to uid 65534"),
              std::string::npos);
    ASSERT_EQ(::chown(path.c_str(), 0, 0), 0);
  }
  WriteFileAtomically(path, std::string(32, '\0'), 0600);
  try {
    ReadSecretKeyFile(path);
    ADD_FAILURE() << "an all-zero key was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("all zero"), std::string::npos) << e.what();
  }
  WriteFileAtomically(path, "short", 0600);
  EXPECT_THROW(ReadSecretKeyFile(path), std::runtime_error);
  ::unlink(path.c_str());
  ::unlink(PublicKeyPathOf(path).c_str());
}

/// A gateway "pumptherm" with one pump whose trip on `winding` is latched (restored from a
/// saved state), with gateway key KeyOf(100) and operators alice (KeyOf(1)), bob (KeyOf(2))
/// and revoked eve (KeyOf(3)); replies land in `replies_`, committed safety states in
/// `commits_`.
class ClearGateway : public ::testing::Test, public OutputSink {
 protected:
  static std::string ConfigText() {
    return fmt::format(R"(
[gateway]
heartbeat_period_s = 0
[[can]]
interface = "can0"
[alarms]
[[alarms.clear_operators]]
name = "alice"
public_key = "{}"
[[alarms.clear_operators]]
name = "bob"
public_key = "{}"
[[alarms.clear_operators]]
name = "eve"
public_key = "{}"
revoked = true
[[pump]]
name = "tmp1"
node_id = 1
thermal_model = "tmp-generic"
)",
                       FormatPublicKey(KeyOf(1).public_key()),
                       FormatPublicKey(KeyOf(2).public_key()),
                       FormatPublicKey(KeyOf(3).public_key()));
  }
  static DaemonConfig Config() {
    return ParseConfig(ConfigText(), std::string(PUMPTHERM_SOURCE_DIR) + "/c.toml");
  }
  static void Keyed(Gateway& g) {
    g.SetGatewayKey(KeyOf(100));
    g.LoadClearKeys("");
  }

  ClearGateway() : gateway_(Config()) {
    Keyed(gateway_);
    gateway_.SetSafetyCommit([this](const std::string& text, std::string* error) {
      // Durable before it acts: the pump is still latched while its clear is committed.
      latched_at_commit_.push_back(Latched());
      commits_.push_back(text);
      if (fail_commits_) *error = "No space left on device";
      return !fail_commits_;
    });
  }

  void SendFrame(std::size_t, std::int64_t, const protocol::CanFrame&) override {}
  bool PublishLcm(const std::string& channel, std::int64_t,
                  const std::vector<std::uint8_t>& b) override {
    if (channel != "PUMPTHERM/tmp1/ALARM_CLEAR_REPLY") return true;  // outputs of an Advance
    Reply r;
    EXPECT_GT(r.decode(b.data(), 0, static_cast<int>(b.size())), 0);
    replies_.push_back(r);
    return true;
  }

  /// Latches trips on the pump through a saved state (the path a restart takes).
  static void Latch(Gateway& g, const std::string& nodes = "'winding'",
                    const std::string& values = "130.0") {
    const std::string text = R"(version = 2
[pump.tmp1]
model = 'tmp-generic'
time_us = 1763776800000000
x_degC = [ 40.0, 40.0, 40.0, 40.0 ]
s_K2 = [ 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0 ]
inputs = { speed_rpm = 0.0, id_A = 0.0, iq_A = 0.0, ambient_degC = 25.0, coolant_degC = 25.0 }
resistance_x = [ 0.28, 0.0, 0.0, 0.0, 0.28, 0.0, 0.0, 0.0 ]
resistance_p = [ 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0 ]
resistance_probability = [ 0.5, 0.5 ]
resistance_rejections = [ 0, 0 ]
resistance_moments = [ 0.0, 0.0, 0.0, 0.0 ]
resistance_blocks = 0
latched_trip_nodes = [ )" + nodes +
                             R"( ]
latched_trip_values_degC = [ )" +
                             values + R"( ]
)";
    std::string warning;
    ASSERT_EQ(g.RestoreState(text, kNowUs, &warning), 1) << warning;
    ASSERT_TRUE(Latched(g));
  }

  /// alice's command, signed for this gateway (or `gateway`, `prefix`).
  static pumptherm::alarm_clear_t Signed(std::int64_t utime, std::int64_t counter,
                                         const std::string& node = "", std::uint8_t key = 1,
                                         const std::string& gateway = "pumptherm",
                                         const std::string& prefix = kPrefix) {
    pumptherm::alarm_clear_t m = Command(utime, counter, node);
    m.gateway = gateway;
    SignCommand(KeyOf(key), KeyOf(100).public_key(), prefix, m);
    return m;
  }

  bool Send(const pumptherm::alarm_clear_t& m) { return gateway_.ClearFromLcm(&m, kNowUs, *this); }
  static std::vector<std::string> LatchedNodes(const Gateway& g) {
    std::vector<std::string> out;
    for (const auto& t : g.pumps()[0]->Save().latched_trips) out.push_back(t.node);
    return out;
  }
  static bool Latched(const Gateway& g) { return !LatchedNodes(g).empty(); }
  bool Latched() const { return Latched(gateway_); }

  Gateway gateway_;
  std::vector<Reply> replies_;
  std::vector<std::string> commits_;
  std::vector<bool> latched_at_commit_;
  bool fail_commits_ = false;
};

TEST_F(ClearGateway, ForgedClearsAreRefusedCountedAndNotAnswered) {
  Latch(gateway_);
  pumptherm::alarm_clear_t none = Command(kNowUs, kNowUs);  // no tag, no signature
  none.key_id = KeyOf(1).key_id();
  pumptherm::alarm_clear_t stranger = Signed(kNowUs, kNowUs, "", 50);  // a key not listed
  // alice's key ID with mallory's tag and signature: the tag fails.
  pumptherm::alarm_clear_t claimed = Signed(kNowUs, kNowUs, "", 50);
  claimed.key_id = KeyOf(1).key_id();
  // A valid tag with a broken signature (only the gateway's key could make that tag).
  pumptherm::alarm_clear_t bad_sig = Signed(kNowUs, kNowUs + 1);
  bad_sig.signature[10] ^= 0x40;
  EXPECT_FALSE(Send(none));
  EXPECT_FALSE(Send(stranger));
  EXPECT_FALSE(Send(claimed));
  EXPECT_FALSE(Send(bad_sig));
  EXPECT_FALSE(gateway_.ClearFromLcm(nullptr, kNowUs, *this));    // does not decode
  EXPECT_FALSE(gateway_.Clear("tmp1", "alice", "no signature"));  // a name alone
  EXPECT_TRUE(Latched());
  EXPECT_EQ(gateway_.counters().clears_refused, 6U);
  EXPECT_EQ(gateway_.counters().clears_unauthenticated, 6U);
  EXPECT_EQ(gateway_.counters().clears_accepted, 0U);
  EXPECT_TRUE(replies_.empty());  // a forger learns nothing and costs no reply
  EXPECT_TRUE(commits_.empty());
  EXPECT_EQ(gateway_.clear_auth().last_counter("tmp1", KeyOf(1).key_id()), 0);
}

TEST_F(ClearGateway, ValidClearIsDurableBeforeItActsAndItsReplayIsRefusedAfterARestart) {
  Latch(gateway_);
  const pumptherm::alarm_clear_t m = Signed(kNowUs - 2'000'000, 100);
  EXPECT_TRUE(Send(m));
  EXPECT_FALSE(Latched());
  ASSERT_EQ(commits_.size(), 1U);
  EXPECT_TRUE(latched_at_commit_[0]);  // committed while still latched: nothing acted before
  std::string problem;
  const auto committed = ParseSafetyState(commits_[0], &problem);
  ASSERT_TRUE(committed) << problem;
  EXPECT_TRUE(committed->latched.at("tmp1").empty());
  EXPECT_EQ(committed->counters.at("tmp1").at(KeyOf(1).key_id()), 100);
  ASSERT_EQ(replies_.size(), 1U);
  EXPECT_EQ(replies_[0].result, Reply::RESULT_ACCEPTED);
  EXPECT_EQ(replies_[0].reason, "latched trip cleared");
  EXPECT_EQ(replies_[0].gateway, "pumptherm");
  EXPECT_EQ(replies_[0].key_id, KeyOf(1).key_id());
  EXPECT_FALSE(replies_[0].trip_latched);
  EXPECT_TRUE(VerifyReply(KeyOf(100).public_key(), kPrefix, replies_[0]));
  EXPECT_FALSE(VerifyReply(KeyOf(101).public_key(), kPrefix, replies_[0]));

  // The same bytes again: refused, no answer, no signature check spent on it.
  Latch(gateway_);
  EXPECT_FALSE(Send(m));
  EXPECT_TRUE(Latched());
  EXPECT_EQ(replies_.size(), 1U);

  // After a restart with the committed safety state: still refused; a new counter clears.
  Gateway restarted(Config());
  Keyed(restarted);
  Latch(restarted);
  restarted.ApplySafetyState(*committed, kNowUs);
  EXPECT_FALSE(Latched(restarted));  // the committed state says cleared
  Latch(restarted);
  EXPECT_FALSE(restarted.ClearFromLcm(&m, kNowUs, *this));
  EXPECT_TRUE(Latched(restarted));
  // bob's counters are his own: his first command is fresh.
  const pumptherm::alarm_clear_t bobs = Signed(kNowUs, 50, "", 2);
  EXPECT_TRUE(restarted.ClearFromLcm(&bobs, kNowUs, *this));
  EXPECT_FALSE(Latched(restarted));
}

TEST_F(ClearGateway, ACommandForAnotherGatewayOrPrefixClearsNothingHere) {
  Latch(gateway_);
  // Signed for gateway "hall2" (same operator key, same pump name): refused by name.
  const pumptherm::alarm_clear_t other = Signed(kNowUs, 10, "", 1, "hall2");
  EXPECT_FALSE(Send(other));
  // The same command with the gateway's name changed to this one: the tag no longer holds.
  pumptherm::alarm_clear_t renamed = other;
  renamed.gateway = "pumptherm";
  EXPECT_FALSE(Send(renamed));
  // Signed for this gateway's name under another channel prefix (replayed onto ours).
  const pumptherm::alarm_clear_t prefixed = Signed(kNowUs, 11, "", 1, "pumptherm", "HALL2");
  EXPECT_FALSE(Send(prefixed));
  EXPECT_TRUE(Latched());
  EXPECT_TRUE(replies_.empty());
  EXPECT_EQ(gateway_.counters().clears_refused, 3U);
}

TEST_F(ClearGateway, TheNodeIsHonoured) {
  Latch(gateway_, "'winding', 'sensor'", "130.0, 90.0");
  // A node that is not latched: refused (answered), nothing cleared, its counter not taken.
  EXPECT_FALSE(Send(Signed(kNowUs, 1, "frame")));
  ASSERT_EQ(replies_.size(), 1U);
  EXPECT_EQ(replies_[0].result, Reply::RESULT_NODE_NOT_LATCHED);
  EXPECT_EQ(LatchedNodes(gateway_), (std::vector<std::string>{"winding", "sensor"}));
  EXPECT_TRUE(commits_.empty());
  // The winding only: the sensor's trip stays latched.
  EXPECT_TRUE(Send(Signed(kNowUs, 2, "winding")));
  EXPECT_EQ(LatchedNodes(gateway_), std::vector<std::string>{"sensor"});
  EXPECT_EQ(replies_.back().result, Reply::RESULT_ACCEPTED);
  EXPECT_EQ(replies_.back().reason, "latched trip of winding cleared");
  EXPECT_TRUE(replies_.back().trip_latched);
  std::string problem;
  const auto committed = ParseSafetyState(commits_.back(), &problem);
  ASSERT_TRUE(committed) << problem;
  ASSERT_EQ(committed->latched.at("tmp1").size(), 1U);
  EXPECT_EQ(committed->latched.at("tmp1")[0].node, "sensor");
  // Empty: every latch.
  EXPECT_TRUE(Send(Signed(kNowUs, 3)));
  EXPECT_FALSE(Latched());
}

TEST_F(ClearGateway, RevokedKeysOutsideTheWindowAndUnsavedClearsAreRefused) {
  Latch(gateway_);
  EXPECT_FALSE(Send(Signed(kNowUs, 1, "", 3)));  // eve's key is revoked: no answer
  EXPECT_TRUE(replies_.empty());
  EXPECT_FALSE(Send(Signed(kNowUs - 31'000'000, 2)));  // window 30 s: answered, signed
  EXPECT_FALSE(Send(Signed(kNowUs + 31'000'000, 3)));
  ASSERT_EQ(replies_.size(), 2U);
  EXPECT_EQ(replies_[0].result, Reply::RESULT_OUTSIDE_WINDOW);
  EXPECT_EQ(replies_[1].result, Reply::RESULT_OUTSIDE_WINDOW);
  fail_commits_ = true;  // a full disk: the clear must not act
  EXPECT_FALSE(Send(Signed(kNowUs, 4)));
  EXPECT_TRUE(Latched());
  EXPECT_EQ(replies_.back().result, Reply::RESULT_NOT_SAVED);
  EXPECT_NE(replies_.back().reason.find("No space left on device"), std::string::npos);
  EXPECT_EQ(gateway_.clear_auth().last_counter("tmp1", KeyOf(1).key_id()), 0);
  fail_commits_ = false;
  EXPECT_TRUE(Send(Signed(kNowUs, 4)));  // the same command once the disk has room
  EXPECT_FALSE(Latched());
  EXPECT_EQ(gateway_.counters().clears_unauthenticated, 0U);
}

TEST_F(ClearGateway, TheSharedKeyIsAMigrationPathOffByDefault) {
  Latch(gateway_);
  ClearKey shared{};
  shared.fill(0x5a);
  pumptherm::alarm_clear_t m = Command(kNowUs, 9);
  SignCommandShared(shared, "operator", kPrefix, m);
  EXPECT_FALSE(Send(m));  // off: refused as an unknown key
  EXPECT_TRUE(replies_.empty());
  DaemonConfig c = Config();
  c.alarms.clear_lcm_sources = {"operator"};
  Gateway allowed(c);
  Keyed(allowed);
  allowed.SetSharedKey(shared);
  Latch(allowed);
  EXPECT_TRUE(allowed.ClearFromLcm(&m, kNowUs, *this));
  EXPECT_FALSE(Latched(allowed));
  ASSERT_EQ(replies_.size(), 1U);
  EXPECT_TRUE(VerifyReply(KeyOf(100).public_key(), kPrefix, replies_[0]));
  pumptherm::alarm_clear_t intruder = Command(kNowUs, 10);
  SignCommandShared(shared, "intruder", kPrefix, intruder);
  EXPECT_FALSE(allowed.ClearFromLcm(&intruder, kNowUs, *this));
}

// The client's exchange (pumptherm clear-trip) against a gateway over one memq:// LCM: the
// command goes out on ALARM_CLEAR, the gateway answers on ALARM_CLEAR_REPLY, the client trusts
// only answers signed by the gateway's key.
TEST_F(ClearGateway, ClientSeesTheGatewaysSignedAnswer) {
  lcm::LCM lcm("memq://");
  ASSERT_TRUE(lcm.good());
  struct Responder : OutputSink {
    lcm::LCM& lcm;
    Gateway& gateway;
    Responder(lcm::LCM& l, Gateway& g) : lcm(l), gateway(g) {}
    void SendFrame(std::size_t, std::int64_t, const protocol::CanFrame&) override {}
    bool PublishLcm(const std::string& channel, std::int64_t,
                    const std::vector<std::uint8_t>& b) override {
      return lcm.publish(channel, b.data(), static_cast<unsigned>(b.size())) == 0;
    }
    void On(const lcm::ReceiveBuffer* rbuf, const std::string&) {
      pumptherm::alarm_clear_t m;
      const int size = static_cast<int>(rbuf->data_size);
      const bool ok = m.decode(rbuf->data, 0, size) == size;
      gateway.ClearFromLcm(ok ? &m : nullptr, kNowUs, *this);
    }
  } responder(lcm, gateway_);
  lcm.subscribe(lcm_channels::AllPumpsPattern(kPrefix, lcm_channels::PumpChannel::kAlarmClear),
                &Responder::On, &responder);
  Latch(gateway_);
  const ClearExchange ok = SendClear(lcm, kPrefix, KeyOf(100).public_key(), Signed(kNowUs, 7), 2.0);
  ASSERT_TRUE(ok.reply.has_value());
  EXPECT_EQ(ok.reply->result, Reply::RESULT_ACCEPTED);
  EXPECT_FALSE(Latched());
  // A client holding another gateway's public key trusts nothing it hears.
  Latch(gateway_);
  const ClearExchange wrong =
      SendClear(lcm, kPrefix, KeyOf(101).public_key(), Signed(kNowUs, 8), 0.5);
  EXPECT_FALSE(wrong.reply.has_value());
  EXPECT_EQ(wrong.untrusted_replies, 1);
  // A replay gets no answer at all.
  const ClearExchange replay =
      SendClear(lcm, kPrefix, KeyOf(100).public_key(), Signed(kNowUs, 7), 0.3);
  EXPECT_FALSE(replay.reply.has_value());
  EXPECT_EQ(replay.untrusted_replies, 0);
}

// An outsider's strings (key ID, comment, gateway) cannot start a journal line of their own.
TEST_F(ClearGateway, WhatCameFromOutsideIsEscapedInTheJournal) {
  Latch(gateway_);
  pumptherm::alarm_clear_t m = Signed(kNowUs, 5);
  m.comment = "ok\n<2>pumpthermd: alarm clear from 'boss' accepted\r";
  SignCommand(KeyOf(1), KeyOf(100).public_key(), kPrefix, m);
  pumptherm::alarm_clear_t forged = Command(kNowUs, 6);
  forged.key_id = "x\n<3>forged line";
  testing::internal::CaptureStderr();
  EXPECT_TRUE(Send(m));
  EXPECT_FALSE(Send(forged));
  const std::string out = testing::internal::GetCapturedStderr();
  std::size_t lines = 0;
  for (char c : out) lines += c == '\n';
  EXPECT_EQ(lines, 2U) << out;
  EXPECT_NE(out.find("ok\\n<2>pumpthermd: alarm clear from 'boss' accepted\\r"), std::string::npos)
      << out;
  EXPECT_NE(out.find("key x\\n<3>forged line (unknown)"), std::string::npos) << out;
}

TEST_F(ClearGateway, AFloodIsLoggedInABurstThenSummarisedOncePerSource) {
  Latch(gateway_);
  auto count = [](const std::string& text, const std::string& what) {
    std::size_t n = 0;
    for (std::size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1))
      ++n;
    return n;
  };
  gateway_.Advance(kNowUs, *this);
  testing::internal::CaptureStderr();
  for (int i = 0; i < 1000; ++i) {
    pumptherm::alarm_clear_t m = Command(kNowUs, kNowUs + i);
    m.key_id = i % 2 ? KeyOf(1).key_id() : "mallory";
    EXPECT_FALSE(Send(m));
  }
  const pumptherm::alarm_clear_t legit = Signed(kNowUs, kNowUs + 5000);
  EXPECT_TRUE(Send(legit));  // inside the flood
  const std::string flood = testing::internal::GetCapturedStderr();
  EXPECT_EQ(gateway_.counters().clears_refused, 1000U);
  EXPECT_EQ(count(flood, "refused: "), 5U) << flood;
  EXPECT_EQ(count(flood, "accepted"), 1U) << flood;
  testing::internal::CaptureStderr();
  gateway_.FlushClearAudit();  // at stop: one line per source
  const std::string stop = testing::internal::GetCapturedStderr();
  EXPECT_EQ(count(stop, "\n"), 2U) << stop;
  EXPECT_NE(
      stop.find("refused alarm clear(s) from alice (key " + KeyOf(1).key_id() + ") not logged"),
      std::string::npos)
      << stop;
  EXPECT_NE(stop.find("from key mallory (unknown) not logged"), std::string::npos) << stop;
  EXPECT_NE(stop.find("bad tag"), std::string::npos) << stop;
}

TEST(ClearAuth, GatewayWithoutASigningKeyRefusesEveryLcmClear) {
  const SigningKey op = KeyOf(1);
  Gateway g(ParseConfig("[alarms]\n[[alarms.clear_operators]]\nname = \"alice\"\npublic_key = \"" +
                            FormatPublicKey(op.public_key()) +
                            "\"\n[[can]]\ninterface = \"can0\"\n[[pump]]\nname = \"tmp1\"\n"
                            "node_id = 1\n",
                        std::string(PUMPTHERM_SOURCE_DIR) + "/c.toml"));
  testing::internal::CaptureStderr();
  g.LoadClearKeys("");  // no signing key configured: a warning, no error
  EXPECT_NE(testing::internal::GetCapturedStderr().find("gateway.signing_key_file is not set"),
            std::string::npos);
  struct Sink : OutputSink {
    int replies = 0;
    void SendFrame(std::size_t, std::int64_t, const protocol::CanFrame&) override {}
    bool PublishLcm(const std::string&, std::int64_t, const std::vector<std::uint8_t>&) override {
      ++replies;
      return true;
    }
  } sink;
  pumptherm::alarm_clear_t m = Command(kNowUs, 1);
  SignCommand(op, KeyOf(100).public_key(), kPrefix, m);
  EXPECT_FALSE(g.ClearFromLcm(&m, kNowUs, sink));
  EXPECT_EQ(sink.replies, 0);
}

TEST(LogRateLimiter, BurstPerWindowThenCountsAndReportsWhatWasHeldBack) {
  LogRateLimiter limit(2, 10.0);
  std::uint64_t held = 99;
  EXPECT_TRUE(limit.Allow(0, &held));
  EXPECT_EQ(held, 0U);
  EXPECT_TRUE(limit.Allow(1'000'000));
  for (int i = 0; i < 7; ++i) EXPECT_FALSE(limit.Allow(2'000'000 + i));
  EXPECT_EQ(limit.TakeHeldBack(9'000'000), 0U);  // the window still runs
  EXPECT_TRUE(limit.Allow(10'000'000, &held));   // a new window: the line carries the 7
  EXPECT_EQ(held, 7U);
  EXPECT_TRUE(limit.Allow(10'500'000, &held));
  EXPECT_EQ(held, 0U);
  EXPECT_FALSE(limit.Allow(11'000'000));
  EXPECT_EQ(limit.TakeHeldBack(20'000'000), 1U);  // no further line came: a summary reports it
  EXPECT_EQ(limit.TakeHeldBack(20'000'000), 0U);
  EXPECT_EQ(limit.held_back_total(), 8U);
  EXPECT_THROW(LogRateLimiter(0, 1.0), std::invalid_argument);
}

TEST(ClearAuth, RefusedCanClearsAreLoggedRateLimitedThenSummarised) {
  Gateway g(
      ParseConfig("[alarms]\nclear_can_interfaces = [\"can0\"]\n[[can]]\ninterface = \"can0\"\n"
                  "[[pump]]\nname = \"tmp1\"\nnode_id = 1\n",
                  std::string(PUMPTHERM_SOURCE_DIR) + "/c.toml"));
  struct Sink : OutputSink {
    void SendFrame(std::size_t, std::int64_t, const protocol::CanFrame&) override {}
    bool PublishLcm(const std::string&, std::int64_t, const std::vector<std::uint8_t>&) override {
      return true;
    }
  } sink;
  auto lines = [](const std::string& text, const std::string& what) {
    std::size_t n = 0;
    for (std::size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1))
      ++n;
    return n;
  };
  g.Advance(kNowUs, sink);
  testing::internal::CaptureStderr();
  for (int i = 0; i < 100; ++i) EXPECT_FALSE(g.Clear("tmp1", "can:can9", "flood"));
  const std::string flood = testing::internal::GetCapturedStderr();
  EXPECT_EQ(g.counters().clears_refused, 100U);
  EXPECT_EQ(lines(flood, "refused (not a configured source)"), 5U) << flood;
  // After the window: a summary of the 95 not logged, then the next refusal is logged again.
  testing::internal::CaptureStderr();
  g.Advance(kNowUs + 61'000'000, sink);
  EXPECT_FALSE(g.Clear("nosuch", "can:can0", ""));
  const std::string after = testing::internal::GetCapturedStderr();
  EXPECT_EQ(lines(after, "95 refused alarm clear(s) from can:can9 not logged"), 1U) << after;
  EXPECT_EQ(lines(after, "alarm clear for unknown pump 'nosuch'"), 1U) << after;
}

TEST(ClearAuth, OperatorKeysAreParsedWithTheirLines) {
  const std::string pk = FormatPublicKey(KeyOf(1).public_key());
  const DaemonConfig c = ParseConfig(
      "[gateway]\nsigning_key_file = \"gw.key\"\n[alarms]\nclear_window_s = 5\n"
      "[[alarms.clear_operators]]\nname = \"alice\"\npublic_key = \"" +
          pk + "\"\nrevoked = true\n",
      "/etc/p.toml");
  EXPECT_EQ(c.gateway.signing_key_file, "/etc/gw.key");  // relative to the configuration
  ASSERT_EQ(c.clear_auth.operators.size(), 1U);
  EXPECT_EQ(c.clear_auth.operators[0].name, "alice");
  EXPECT_TRUE(c.clear_auth.operators[0].revoked);
  EXPECT_EQ(c.clear_auth.operators[0].public_key, KeyOf(1).public_key());
  EXPECT_EQ(c.clear_auth.window_s, 5.0);
  EXPECT_FALSE(c.clear_auth.allow_shared_key);
  try {
    ParseConfig("[alarms]\n[[alarms.clear_operators]]\nname = \"bob\"\npublic_key = \"xyz\"\n",
                "/etc/p.toml");
    ADD_FAILURE() << "a bad public key was accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(
        std::string(e.what()).find("/etc/p.toml:4: key 'alarms.clear_operators[0].public_key'"),
        std::string::npos)
        << e.what();
  }
  EXPECT_THROW(
      ParseConfig("[alarms]\n[[alarms.clear_operators]]\nname = \"a\"\npublic_key = \"" + pk +
                      "\"\n[[alarms.clear_operators]]\nname = \"b\"\npublic_key = \"" + pk + "\"\n",
                  "/etc/p.toml"),
      ConfigError);  // one key, two names
  EXPECT_THROW(ParseConfig("[alarms]\nclear_window_s = 0.5\n", "/etc/p.toml"), ConfigError);
  EXPECT_THROW(ParseConfig("[gateway]\nlost_safety_state = \"ignore\"\n", "/etc/p.toml"),
               ConfigError);
}

/// A gateway key file written by keygen, loaded as the daemon does (directly, or from systemd's
/// credential copy), its permissions checked.
TEST(ClearAuth, GatewayKeyFileIsCheckedAndASystemdCredentialIsPreferred) {
  const std::string dir = test_files::TestTempDir("gwkey");
  ::chmod(dir.c_str(), 0700);
  const std::string path = dir + "/gateway.key";
  ::unlink(path.c_str());
  ::unlink(PublicKeyPathOf(path).c_str());
  WriteKeyFiles(path, KeyOf(100), "gw");
  const DaemonConfig c =
      ParseConfig("[gateway]\nsigning_key_file = \"gateway.key\"\n", dir + "/pumpthermd.toml");
  EXPECT_EQ(LoadConfiguredGatewayKey(c, "")->public_key(), KeyOf(100).public_key());
  const std::string creds = dir + "/creds";
  ::mkdir(creds.c_str(), 0700);
  const Seed other = SeedOf(120);
  WriteFileAtomically(creds + "/" + kGatewayKeyCredential, std::string(other.begin(), other.end()),
                      0400);
  EXPECT_EQ(LoadConfiguredGatewayKey(c, creds)->public_key(), KeyOf(120).public_key());
  WriteFileAtomically(creds + "/" + kGatewayKeyCredential, std::string(kNoCredential), 0400);
  EXPECT_EQ(LoadConfiguredGatewayKey(c, creds)->public_key(), KeyOf(100).public_key());
  ASSERT_EQ(::chmod(path.c_str(), 0644), 0);
  try {
    LoadConfiguredGatewayKey(c, creds);
    ADD_FAILURE() << "a world-readable gateway key was accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find(dir +
                                         "/pumpthermd.toml:2: key "
                                         "'gateway.signing_key_file': " +
                                         path + " is open to its group or others (mode 0644)"),
              std::string::npos)
        << e.what();
  }
  ::unlink((creds + "/" + kGatewayKeyCredential).c_str());
  ::rmdir(creds.c_str());
  ::unlink(path.c_str());
  ::unlink(PublicKeyPathOf(path).c_str());
}

}  // namespace
}  // namespace pumptherm::daemon
