#include "daemon/alarm_clear_auth.hpp"

#include <fmt/format.h>
#include <grp.h>
#include <sodium.h>
#include <sys/stat.h>
#include <toml++/toml.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <lcm/lcm-cpp.hpp>
#include <stdexcept>
#include <system_error>
#include <vector>

#include "daemon/config.hpp"
#include "daemon/state_store.hpp"
#include "protocol/lcm/channels.hpp"

namespace pumptherm::daemon {
namespace {

static_assert(kClearKeyBytes == crypto_auth_KEYBYTES, "the clear key is a crypto_auth key");
static_assert(crypto_auth_BYTES == 32, "alarm_clear_t.mac holds a crypto_auth tag");

/// The bytes an authentication code covers (docs/lcm.md, "Authentication code"): a domain
/// string naming the type, then each field in order, integers as 8 bytes big-endian and
/// strings as a 4-byte big-endian length and their bytes, so no two messages share a layout.
class MacInput {
 public:
  explicit MacInput(std::string_view domain) {
    // libsodium asks for sodium_init() before any other call; it is idempotent and thread-safe.
    static const int init = sodium_init();
    if (init < 0) throw std::runtime_error("libsodium cannot start (sodium_init)");
    bytes_.assign(domain.begin(), domain.end());
    bytes_.push_back(0);
  }
  MacInput& Int(std::int64_t v) {
    const auto u = static_cast<std::uint64_t>(v);
    for (int shift = 56; shift >= 0; shift -= 8)
      bytes_.push_back(static_cast<std::uint8_t>(u >> shift));
    return *this;
  }
  MacInput& Text(const std::string& s) {
    const auto n = static_cast<std::uint32_t>(s.size());
    for (int shift = 24; shift >= 0; shift -= 8)
      bytes_.push_back(static_cast<std::uint8_t>(n >> shift));
    bytes_.insert(bytes_.end(), s.begin(), s.end());
    return *this;
  }
  std::array<std::uint8_t, 32> Mac(const ClearKey& key) const {
    std::array<std::uint8_t, 32> out{};
    crypto_auth(out.data(), bytes_.data(), bytes_.size(), key.data());
    return out;
  }
  bool Verify(const ClearKey& key, const std::uint8_t* mac) const {
    return crypto_auth_verify(mac, bytes_.data(), bytes_.size(), key.data()) == 0;
  }

 private:
  std::vector<std::uint8_t> bytes_;
};

MacInput RequestInput(const pumptherm::alarm_clear_t& m) {
  MacInput in("pumptherm.alarm_clear_t.1");
  in.Int(m.utime).Text(m.pump).Text(m.node).Text(m.source).Text(m.comment).Int(m.counter);
  return in;
}

MacInput ReplyInput(const pumptherm::alarm_clear_reply_t& m) {
  MacInput in("pumptherm.alarm_clear_reply_t.1");
  in.Int(m.utime)
      .Text(m.pump)
      .Int(m.counter)
      .Int(m.result)
      .Text(m.reason)
      .Int(m.last_counter)
      .Int(m.trip_latched ? 1 : 0);
  return in;
}

/// Whether group `gid` (as /etc/group numbers it) is mapped into this process's user
/// namespace, and as what. Outside any user namespace every group is mapped to itself.
std::optional<gid_t> GidHere(gid_t gid) {
  std::ifstream map("/proc/self/gid_map");
  if (!map) return gid;
  std::uint64_t inside = 0, outside = 0, count = 0;
  while (map >> inside >> outside >> count) {
    if (gid >= outside && gid - outside < count)
      return static_cast<gid_t>(inside + (gid - outside));
  }
  return std::nullopt;
}

/// The id of group `name`, or nullopt when there is none.
std::optional<gid_t> GroupId(const std::string& name) {
  std::vector<char> buf(16384);
  for (;;) {
    struct group gr {};
    struct group* found = nullptr;
    const int err = ::getgrnam_r(name.c_str(), &gr, buf.data(), buf.size(), &found);
    if (err == ERANGE && buf.size() < (1U << 20)) {
      buf.resize(buf.size() * 4);
      continue;
    }
    if (!found) return std::nullopt;
    return found->gr_gid;
  }
}

std::string ModeText(mode_t mode) { return fmt::format("{:04o}", mode & 07777); }

}  // namespace

std::string ClearKeyFileProblem(const std::string& path, const std::string& group) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0)
    return fmt::format("cannot stat {}: {}", path, std::strerror(errno));
  if (!S_ISREG(st.st_mode)) return fmt::format("{} is not a regular file", path);
  if ((st.st_mode & S_IRWXO) != 0) {
    return fmt::format(
        "{} is open to others (mode {}): anyone on this host could clear trips; "
        "make it 0640 (chmod 0640, chgrp {})",
        path, ModeText(st.st_mode), group.empty() ? "<operators>" : group);
  }
  if ((st.st_mode & S_IWGRP) != 0) {
    return fmt::format("{} is writable by its group (mode {}): make it 0640", path,
                       ModeText(st.st_mode));
  }
  if (group.empty()) return "";
  const std::optional<gid_t> gid = GroupId(group);
  if (!gid) return fmt::format("group '{}' (alarms.clear_key_group) does not exist", group);
  const std::optional<gid_t> here = GidHere(*gid);
  if (here && st.st_gid != *here) {
    return fmt::format("{} belongs to group {}, not to '{}' (gid {}): chgrp {} {}", path, st.st_gid,
                       group, *gid, group, path);
  }
  return "";
}

ClearKey ReadClearKeyFile(const std::string& path) {
  std::optional<std::string> text;
  try {
    text = ReadFileIfExists(path);
  } catch (const std::system_error& e) {
    throw std::runtime_error(e.what());
  }
  if (!text) throw std::runtime_error(fmt::format("cannot open {}: it does not exist", path));
  if (text->size() != kClearKeyBytes) {
    throw std::runtime_error(
        fmt::format("{} holds {} bytes; a clear key is {} random bytes "
                    "(head -c 32 /dev/urandom > FILE)",
                    path, text->size(), kClearKeyBytes));
  }
  ClearKey key{};
  std::memcpy(key.data(), text->data(), key.size());
  return key;
}

std::string CredentialsDirectory() {
  const char* dir = std::getenv("CREDENTIALS_DIRECTORY");
  return dir ? dir : "";
}

std::optional<ClearKey> LoadConfiguredClearKey(const DaemonConfig& config,
                                               const std::string& credentials_dir) {
  const ClearAuthConfig& c = config.clear_auth;
  if (c.key_file.empty()) return std::nullopt;
  auto fail = [&](const std::string& what) {
    throw ConfigError(
        fmt::format("{}:{}: key 'alarms.clear_key_file': {}", config.source, c.line, what));
  };
  if (const std::string problem = ClearKeyFileProblem(c.key_file, c.key_group); !problem.empty())
    fail(problem);
  // Under the shipped unit, systemd (as root) hands the file over as a credential: the
  // service's dynamic user is not in the operators' group. kNoClearKeyCredential means systemd
  // found no file when the service started; the file itself is read then.
  std::string path = c.key_file;
  if (!credentials_dir.empty()) {
    const std::string copy = credentials_dir + "/" + kClearKeyCredential;
    std::optional<std::string> text;
    try {
      text = ReadFileIfExists(copy);
    } catch (const std::system_error& e) {
      fail(e.what());
    }
    if (text && *text != kNoClearKeyCredential) path = copy;
  }
  try {
    return ReadClearKeyFile(path);
  } catch (const std::runtime_error& e) {
    fail(e.what());
  }
  return std::nullopt;
}

std::array<std::uint8_t, 32> ClearMac(const ClearKey& key, const pumptherm::alarm_clear_t& m) {
  return RequestInput(m).Mac(key);
}

std::array<std::uint8_t, 32> ClearReplyMac(const ClearKey& key,
                                           const pumptherm::alarm_clear_reply_t& m) {
  return ReplyInput(m).Mac(key);
}

void Sign(const ClearKey& key, pumptherm::alarm_clear_t& m) {
  const auto mac = ClearMac(key, m);
  std::memcpy(m.mac, mac.data(), mac.size());
}

void Sign(const ClearKey& key, pumptherm::alarm_clear_reply_t& m) {
  const auto mac = ClearReplyMac(key, m);
  std::memcpy(m.mac, mac.data(), mac.size());
}

bool Verify(const ClearKey& key, const pumptherm::alarm_clear_t& m) {
  return RequestInput(m).Verify(key, m.mac);
}

bool Verify(const ClearKey& key, const pumptherm::alarm_clear_reply_t& m) {
  return ReplyInput(m).Verify(key, m.mac);
}

ClearExchange SendClear(lcm::LCM& lcm, const std::string& prefix, const ClearKey& key,
                        pumptherm::alarm_clear_t m, double timeout_s) {
  using lcm_channels::PumpChannel;
  using lcm_channels::PumpChannelName;
  Sign(key, m);
  struct Listener {
    const ClearKey& key;
    std::int64_t counter;
    ClearExchange out;
    void On(const lcm::ReceiveBuffer* rbuf, const std::string&) {
      pumptherm::alarm_clear_reply_t r{};
      const int size = static_cast<int>(rbuf->data_size);
      if (r.decode(rbuf->data, 0, size) != size) return;
      if (r.counter != counter) return;
      if (Verify(key, r)) {
        out.reply = r;
      } else {
        ++out.untrusted_replies;
        out.untrusted_reason = r.reason;
      }
    }
  } listener{key, m.counter, {}};
  lcm::Subscription* sub = lcm.subscribe(
      PumpChannelName(prefix, m.pump, PumpChannel::kAlarmClearReply), &Listener::On, &listener);
  if (lcm.publish(PumpChannelName(prefix, m.pump, PumpChannel::kAlarmClear), &m) != 0) {
    lcm.unsubscribe(sub);
    throw std::runtime_error(
        fmt::format("LCM: cannot publish the clear command: {}", std::strerror(errno)));
  }
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (!listener.out.reply) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) break;
    lcm.handleTimeout(static_cast<int>(std::min<std::int64_t>(left.count(), 100)));
  }
  lcm.unsubscribe(sub);
  return listener.out;
}

std::int8_t ClearAuthenticator::Check(const pumptherm::alarm_clear_t& m, bool source_allowed,
                                      std::int64_t now_us, std::string* reason) {
  using R = pumptherm::alarm_clear_reply_t;
  if (!key_) {
    *reason = "no clear key is configured (alarms.clear_key_file): LCM clears are off";
    return R::RESULT_NO_KEY;
  }
  if (!Verify(*key_, m)) {
    *reason = "no or a wrong authentication code";
    return R::RESULT_BAD_MAC;
  }
  if (!source_allowed) {
    *reason = fmt::format("source '{}' is not in alarms.clear_lcm_sources", m.source);
    return R::RESULT_SOURCE_REFUSED;
  }
  // Written so that no subtraction can overflow, whatever utime holds.
  const bool too_old = m.utime < now_us && now_us - window_us_ > m.utime;
  const bool too_new = m.utime > now_us && m.utime - window_us_ > now_us;
  if (too_old || too_new) {
    *reason = fmt::format("its time is {:.1f} s from the gateway's clock (window {:.0f} s)",
                          (static_cast<double>(m.utime) - static_cast<double>(now_us)) * 1e-6,
                          window_us_ * 1e-6);
    return R::RESULT_OUTSIDE_WINDOW;
  }
  const std::int64_t last = last_counter(m.pump);
  if (m.counter <= last) {
    *reason =
        fmt::format("counter {} is not above the last accepted {} (a replay?)", m.counter, last);
    return R::RESULT_REPLAYED;
  }
  last_counter_[m.pump] = m.counter;
  *reason = "authenticated";
  return R::RESULT_ACCEPTED;
}

std::int64_t ClearAuthenticator::last_counter(const std::string& pump) const {
  const auto it = last_counter_.find(pump);
  return it == last_counter_.end() ? 0 : it->second;
}

pumptherm::alarm_clear_reply_t ClearAuthenticator::Reply(const pumptherm::alarm_clear_t& m,
                                                         std::int8_t result,
                                                         const std::string& reason,
                                                         bool trip_latched,
                                                         std::int64_t now_us) const {
  pumptherm::alarm_clear_reply_t r;
  r.utime = now_us;
  r.pump = m.pump;
  r.counter = m.counter;
  r.result = result;
  r.reason = reason;
  r.last_counter = last_counter(m.pump);
  r.trip_latched = trip_latched;
  std::memset(r.mac, 0, sizeof r.mac);
  if (key_) Sign(*key_, r);
  return r;
}

void ClearAuthenticator::Save(toml::table& root) const {
  toml::table counters;
  for (const auto& [pump, counter] : last_counter_) counters.insert(pump, counter);
  root.insert("clear_auth", toml::table{{"version", 1}, {"last_counter", std::move(counters)}});
}

std::string ClearAuthenticator::Restore(const toml::table& root) {
  const toml::table* t = root["clear_auth"].as_table();
  if (!t) return "";
  if ((*t)["version"].value_or<std::int64_t>(0) != 1) {
    return "clear_auth has an unknown version: clear counters start at 0";
  }
  const toml::table* counters = (*t)["last_counter"].as_table();
  if (!counters) return "clear_auth.last_counter is missing: clear counters start at 0";
  std::string bad;
  for (const auto& [pump, node] : *counters) {
    const auto v = node.value<std::int64_t>();
    if (!v) {
      bad += (bad.empty() ? "" : ", ") + std::string(pump.str());
      continue;
    }
    std::int64_t& last = last_counter_[std::string(pump.str())];
    last = std::max(last, *v);
  }
  return bad.empty() ? "" : "clear_auth.last_counter of " + bad + " is not an integer: ignored";
}

}  // namespace pumptherm::daemon
