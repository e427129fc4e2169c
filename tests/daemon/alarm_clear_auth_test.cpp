// Authenticated LCM alarm clears (docs/threat-model.md): a latched trip clears only with a
// command signed with the clear key, inside the time window, with a new counter; spoofed and
// replayed commands are refused and counted, also after a restart; the key file's permissions
// are checked when the key is loaded.
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

namespace pumptherm::daemon {
namespace {

using Reply = pumptherm::alarm_clear_reply_t;
constexpr std::int64_t kNowUs = 1'763'776'803'000'000;

ClearKey Key(std::uint8_t first) {
  ClearKey k{};
  for (std::size_t i = 0; i < k.size(); ++i) k[i] = static_cast<std::uint8_t>(first + i);
  return k;
}

pumptherm::alarm_clear_t Command(std::int64_t utime, std::int64_t counter,
                                 const std::string& source = "operator") {
  pumptherm::alarm_clear_t m;
  m.utime = utime;
  m.pump = "tmp1";
  m.node = "";
  m.source = source;
  m.comment = "checked";
  m.counter = counter;
  std::fill(std::begin(m.mac), std::end(m.mac), std::uint8_t{0});
  return m;
}

std::string Hex(const std::uint8_t* p, std::size_t n) {
  std::string out;
  char b[3];
  for (std::size_t i = 0; i < n; ++i) {
    std::snprintf(b, sizeof b, "%02x", p[i]);
    out += b;
  }
  return out;
}

// The layout of docs/lcm.md ("Authentication code"), checked against an independent HMAC:
// Python's hmac.new(bytes(range(32)), layout, hashlib.sha512).digest()[:32] over the same
// command gives d28746c3...5fe6 (crypto_auth is HMAC-SHA-512 truncated to 256 bits).
TEST(ClearAuth, CodeFollowsTheDocumentedLayout) {
  pumptherm::alarm_clear_t m = Command(kNowUs, kNowUs);
  Sign(Key(0), m);
  EXPECT_EQ(Hex(m.mac, 32), "d28746c3727f08964495c7d20fa1a2b859f25ecdfdd588f63d330cec72125fe6");
  EXPECT_TRUE(Verify(Key(0), m));
  // Every field is covered.
  for (int field = 0; field < 6; ++field) {
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
        t.source = "operatorx";
        break;
      case 4:
        t.comment += ".";
        break;
      default:
        ++t.counter;
        break;
    }
    EXPECT_FALSE(Verify(Key(0), t)) << "field " << field;
  }
  EXPECT_FALSE(Verify(Key(1), m));
}

/// A gateway with one pump whose trip is latched (restored from a saved state with one), keyed
/// with Key(1); replies land in `replies`.
class ClearGateway : public ::testing::Test, public OutputSink {
 protected:
  static constexpr const char* kConfig = R"(
[gateway]
heartbeat_period_s = 0
[[can]]
interface = "can0"
[alarms]
clear_lcm_sources = ["operator"]
clear_key_file = "clear.key"
clear_key_group = "root"
[[pump]]
name = "tmp1"
node_id = 1
thermal_model = "tmp-generic"
)";

  static DaemonConfig Config() {
    return ParseConfig(kConfig, std::string(PUMPTHERM_SOURCE_DIR) + "/c.toml");
  }

  ClearGateway() : gateway_(Config()) { gateway_.SetClearKey(Key(1)); }

  void SendFrame(std::size_t, std::int64_t, const protocol::CanFrame&) override {}
  bool PublishLcm(const std::string& channel, std::int64_t,
                  const std::vector<std::uint8_t>& b) override {
    Reply r;
    EXPECT_EQ(channel, "PUMPTHERM/tmp1/ALARM_CLEAR_REPLY");
    EXPECT_GT(r.decode(b.data(), 0, static_cast<int>(b.size())), 0);
    replies_.push_back(r);
    return true;
  }

  /// Latches a trip on the pump through a saved state (the path a restart takes).
  static void Latch(Gateway& g) {
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
latched_trip_nodes = [ 'winding' ]
latched_trip_values_degC = [ 130.0 ]
)";
    std::string warning;
    ASSERT_EQ(g.RestoreState(text, kNowUs, &warning), 1) << warning;
    ASSERT_TRUE(Latched(g));
  }

  bool Send(const pumptherm::alarm_clear_t& m) { return gateway_.ClearFromLcm(&m, kNowUs, *this); }
  static bool Latched(const Gateway& g) { return !g.pumps()[0]->Save().latched_trips.empty(); }
  bool Latched() const { return Latched(gateway_); }

  Gateway gateway_;
  std::vector<Reply> replies_;
};

TEST_F(ClearGateway, SpoofedClearsFromAnAcceptedSourceAreRefusedAndCounted) {
  Latch(gateway_);
  pumptherm::alarm_clear_t none = Command(kNowUs, 10);  // no code at all
  pumptherm::alarm_clear_t wrong = Command(kNowUs, 11);
  Sign(Key(2), wrong);  // a code made with another key
  EXPECT_FALSE(Send(none));
  EXPECT_FALSE(Send(wrong));
  EXPECT_FALSE(gateway_.ClearFromLcm(nullptr, kNowUs, *this));  // does not decode
  EXPECT_FALSE(gateway_.Clear("tmp1", "operator", "no code"));  // a source name alone
  EXPECT_TRUE(Latched());
  EXPECT_EQ(gateway_.counters().clears_refused, 4U);
  EXPECT_EQ(gateway_.counters().clears_unauthenticated, 4U);
  EXPECT_EQ(gateway_.counters().clears_accepted, 0U);
  ASSERT_EQ(replies_.size(), 2U);
  for (const Reply& r : replies_) {
    EXPECT_EQ(r.result, Reply::RESULT_BAD_MAC);
    EXPECT_TRUE(r.trip_latched);
    EXPECT_TRUE(Verify(Key(1), r));  // a client can trust the answer
  }
  EXPECT_EQ(gateway_.clear_auth().last_counter("tmp1"), 0);  // refused counters are not taken
}

TEST_F(ClearGateway, ValidClearClearsAndItsReplayIsRefusedAlsoAfterARestart) {
  Latch(gateway_);
  pumptherm::alarm_clear_t m = Command(kNowUs - 2'000'000, 100);
  Sign(Key(1), m);
  EXPECT_TRUE(Send(m));
  EXPECT_FALSE(Latched());
  ASSERT_EQ(replies_.size(), 1U);
  EXPECT_EQ(replies_[0].result, Reply::RESULT_ACCEPTED);
  EXPECT_EQ(replies_[0].reason, "latched trip cleared");
  EXPECT_EQ(replies_[0].counter, 100);
  EXPECT_FALSE(replies_[0].trip_latched);
  EXPECT_TRUE(Verify(Key(1), replies_[0]));

  // The same bytes again: refused, the reply names the counter to exceed.
  Latch(gateway_);
  EXPECT_FALSE(Send(m));
  EXPECT_TRUE(Latched());
  ASSERT_EQ(replies_.size(), 2U);
  EXPECT_EQ(replies_[1].result, Reply::RESULT_REPLAYED);
  EXPECT_EQ(replies_[1].last_counter, 100);

  // After a restart (the saved state carries the counter) still refused; a new counter clears.
  const std::string saved = gateway_.SaveState();
  EXPECT_NE(saved.find("[clear_auth]"), std::string::npos) << saved;
  Gateway restarted(Config());
  restarted.SetClearKey(Key(1));
  std::string warning;
  restarted.RestoreState(saved, kNowUs, &warning);
  EXPECT_EQ(warning, "");
  Latch(restarted);
  EXPECT_FALSE(restarted.ClearFromLcm(&m, kNowUs, *this));
  EXPECT_EQ(replies_.back().result, Reply::RESULT_REPLAYED);
  pumptherm::alarm_clear_t next = Command(kNowUs, 101);
  Sign(Key(1), next);
  EXPECT_TRUE(restarted.ClearFromLcm(&next, kNowUs, *this));
  EXPECT_FALSE(Latched(restarted));
}

TEST_F(ClearGateway, ValidCodeOutsideTheWindowOrFromAnotherSourceIsRefused) {
  Latch(gateway_);
  pumptherm::alarm_clear_t late = Command(kNowUs - 31'000'000, 1);  // window 30 s
  pumptherm::alarm_clear_t early = Command(kNowUs + 31'000'000, 2);
  pumptherm::alarm_clear_t other = Command(kNowUs, 3, "intruder");
  for (auto* m : {&late, &early, &other}) Sign(Key(1), *m);
  EXPECT_FALSE(Send(late));
  EXPECT_FALSE(Send(early));
  EXPECT_FALSE(Send(other));
  EXPECT_TRUE(Latched());
  ASSERT_EQ(replies_.size(), 3U);
  EXPECT_EQ(replies_[0].result, Reply::RESULT_OUTSIDE_WINDOW);
  EXPECT_EQ(replies_[1].result, Reply::RESULT_OUTSIDE_WINDOW);
  EXPECT_EQ(replies_[2].result, Reply::RESULT_SOURCE_REFUSED);
  EXPECT_EQ(gateway_.counters().clears_unauthenticated, 0U);
}

// The client's exchange (pumptherm clear-trip) against a gateway over one memq:// LCM: the
// command goes out on ALARM_CLEAR, the gateway answers on ALARM_CLEAR_REPLY, the client trusts
// only answers signed with its key.
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
  lcm.subscribe(lcm_channels::AllPumpsPattern("PUMPTHERM", lcm_channels::PumpChannel::kAlarmClear),
                &Responder::On, &responder);
  Latch(gateway_);
  const ClearExchange ok = SendClear(lcm, "PUMPTHERM", Key(1), Command(kNowUs, 7), 2.0);
  ASSERT_TRUE(ok.reply.has_value());
  EXPECT_EQ(ok.reply->result, Reply::RESULT_ACCEPTED);
  EXPECT_FALSE(Latched());
  const ClearExchange again = SendClear(lcm, "PUMPTHERM", Key(1), Command(kNowUs, 7), 2.0);
  ASSERT_TRUE(again.reply.has_value());
  EXPECT_EQ(again.reply->result, Reply::RESULT_REPLAYED);
  EXPECT_EQ(again.reply->last_counter, 7);
  // Signed with another key: the gateway refuses, and its answer is not trusted by the client.
  Latch(gateway_);
  const ClearExchange other = SendClear(lcm, "PUMPTHERM", Key(2), Command(kNowUs, 8), 0.5);
  EXPECT_FALSE(other.reply.has_value());
  EXPECT_EQ(other.untrusted_replies, 1);
  EXPECT_EQ(other.untrusted_reason, "no or a wrong authentication code");
  EXPECT_TRUE(Latched());
}

TEST(ClearAuth, GatewayWithoutAKeyRefusesEveryLcmClear) {
  Gateway g(
      ParseConfig("[alarms]\nclear_lcm_sources = [\"operator\"]\n[[can]]\ninterface = \"can0\"\n"
                  "[[pump]]\nname = \"tmp1\"\nnode_id = 1\n",
                  std::string(PUMPTHERM_SOURCE_DIR) + "/c.toml"));
  g.LoadClearKey("");  // no key file configured: a warning, no error
  struct Sink : OutputSink {
    std::int8_t result = -1;
    void SendFrame(std::size_t, std::int64_t, const protocol::CanFrame&) override {}
    bool PublishLcm(const std::string&, std::int64_t, const std::vector<std::uint8_t>& b) override {
      Reply r;
      if (r.decode(b.data(), 0, static_cast<int>(b.size())) > 0) result = r.result;
      return true;
    }
  } sink;
  pumptherm::alarm_clear_t m = Command(kNowUs, 1);
  Sign(Key(1), m);
  EXPECT_FALSE(g.ClearFromLcm(&m, kNowUs, sink));
  EXPECT_EQ(sink.result, Reply::RESULT_NO_KEY);
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

TEST(ClearAuth, RefusedClearsAreLoggedRateLimitedWithTheCountOfTheRest) {
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
  EXPECT_EQ(lines(after, "95 refused alarm clear(s) not logged"), 1U) << after;
  EXPECT_EQ(lines(after, "alarm clear for unknown pump 'nosuch'"), 1U) << after;
}

TEST(ClearAuth, StateWithoutCountersLoadsAndCountersNeverGoDown) {
  ClearAuthenticator a(30.0);
  EXPECT_EQ(a.Restore(toml::parse("version = 2\n")), "");  // a state file from before
  EXPECT_EQ(a.last_counter("tmp1"), 0);
  EXPECT_EQ(a.Restore(toml::parse("[clear_auth]\nversion = 1\nlast_counter = { tmp1 = 50 }\n")),
            "");
  EXPECT_EQ(a.Restore(toml::parse("[clear_auth]\nversion = 1\nlast_counter = { tmp1 = 7 }\n")), "");
  EXPECT_EQ(a.last_counter("tmp1"), 50);
  EXPECT_NE(a.Restore(toml::parse("[clear_auth]\nversion = 9\n")).find("unknown version"),
            std::string::npos);
  EXPECT_NE(a.Restore(toml::parse("[clear_auth]\nversion = 1\nlast_counter = { tmp1 = 'x' }\n"))
                .find("tmp1"),
            std::string::npos);
}

/// A temporary directory with a key file of mode `mode`, owned by the caller's group.
class KeyFile : public ::testing::Test {
 protected:
  void SetUp() override {
    char t[] = "/tmp/pumptherm-key-XXXXXX";
    ASSERT_NE(::mkdtemp(t), nullptr);
    dir_ = t;
    path_ = dir_ + "/clear.key";
    const ClearKey k = Key(9);
    WriteFileAtomically(path_, std::string(k.begin(), k.end()), 0640);
    const struct group* g = ::getgrgid(::getegid());
    ASSERT_NE(g, nullptr);
    group_ = g->gr_name;
  }
  void TearDown() override {
    ::unlink(path_.c_str());
    ::unlink((dir_ + "/" + kClearKeyCredential).c_str());
    ::rmdir(dir_.c_str());
  }
  DaemonConfig Config(const std::string& group) const {
    return ParseConfig(
        "[alarms]\nclear_lcm_sources = [\"operator\"]\nclear_key_file = \"clear.key\"\n"
        "clear_key_group = \"" +
            group + "\"\n",
        dir_ + "/pumpthermd.toml");
  }
  std::string dir_, path_, group_;
};

TEST_F(KeyFile, PermissionsAreCheckedWhenTheKeyIsLoaded) {
  EXPECT_EQ(ClearKeyFileProblem(path_, group_), "");
  EXPECT_EQ(LoadConfiguredClearKey(Config(group_), ""), Key(9));
  ASSERT_EQ(::chmod(path_.c_str(), 0644), 0);  // world-readable: a configuration error
  EXPECT_NE(ClearKeyFileProblem(path_, group_).find("open to others (mode 0644)"),
            std::string::npos);
  try {
    LoadConfiguredClearKey(Config(group_), "");
    ADD_FAILURE() << "a world-readable key was accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(
        std::string(e.what()).find(dir_ + "/pumpthermd.toml:3: key 'alarms.clear_key_file': " +
                                   path_ + " is open to others (mode 0644)"),
        std::string::npos)
        << e.what();
  }
  ASSERT_EQ(::chmod(path_.c_str(), 0660), 0);
  EXPECT_NE(ClearKeyFileProblem(path_, group_).find("writable by its group (mode 0660)"),
            std::string::npos);
  ASSERT_EQ(::chmod(path_.c_str(), 0600), 0);
  EXPECT_EQ(ClearKeyFileProblem(path_, group_), "");
  EXPECT_NE(ClearKeyFileProblem(path_, "no-such-group-pumptherm").find("does not exist"),
            std::string::npos);
  // Another existing group than the file's.
  const std::string other = group_ == "root" ? "daemon" : "root";
  if (::getgrnam(other.c_str())) {
    EXPECT_NE(ClearKeyFileProblem(path_, other).find("not to '" + other + "'"), std::string::npos);
  }
  EXPECT_NE(ClearKeyFileProblem(dir_ + "/missing.key", group_).find("cannot stat"),
            std::string::npos);
}

TEST_F(KeyFile, WrongSizeIsAnErrorAndASystemdCredentialIsPreferred) {
  WriteFileAtomically(path_, "short\n", 0640);
  EXPECT_THROW(LoadConfiguredClearKey(Config(group_), ""), ConfigError);
  // systemd's copy (LoadCredential=) is read when present and non-empty; the file's
  // permissions are still checked.
  const ClearKey k = Key(40);
  WriteFileAtomically(dir_ + "/" + kClearKeyCredential, std::string(k.begin(), k.end()), 0400);
  EXPECT_EQ(LoadConfiguredClearKey(Config(group_), dir_), Key(40));
  // The unit's SetCredential= fallback: the file itself is read (here: the short one).
  WriteFileAtomically(dir_ + "/" + kClearKeyCredential, std::string(kNoClearKeyCredential), 0400);
  EXPECT_THROW(LoadConfiguredClearKey(Config(group_), dir_), ConfigError);
  const ClearKey f = Key(60);
  WriteFileAtomically(path_, std::string(f.begin(), f.end()), 0640);
  EXPECT_EQ(LoadConfiguredClearKey(Config(group_), dir_), Key(60));
}

TEST(ClearAuth, KeyKeysAreParsedAndAGroupIsRequired) {
  // Sources without a key parse (the gateway warns and refuses every LCM clear: NO_KEY above).
  EXPECT_EQ(ParseConfig("[alarms]\nclear_lcm_sources = [\"operator\"]\n", "/etc/p.toml")
                .clear_auth.key_file,
            "");
  EXPECT_THROW(ParseConfig("[alarms]\nclear_key_file = \"k\"\n", "/etc/p.toml"),
               ConfigError);  // no group
  const DaemonConfig c = ParseConfig(
      "[alarms]\nclear_key_file = \"k\"\nclear_key_group = \"ops\"\nclear_window_s = 5\n",
      "/etc/p.toml");
  EXPECT_EQ(c.clear_auth.key_file, "/etc/k");  // relative to the configuration's directory
  EXPECT_EQ(c.clear_auth.key_group, "ops");
  EXPECT_EQ(c.clear_auth.window_s, 5.0);
  EXPECT_THROW(ParseConfig("[alarms]\nclear_window_s = 0.5\n", "/etc/p.toml"), ConfigError);
}

}  // namespace
}  // namespace pumptherm::daemon
