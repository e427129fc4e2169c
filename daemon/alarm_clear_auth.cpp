#include "daemon/alarm_clear_auth.hpp"

#include <fmt/format.h>
#include <grp.h>
#include <sodium.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <lcm/lcm-cpp.hpp>
#include <stdexcept>
#include <system_error>

#include "daemon/config.hpp"
#include "daemon/state_store.hpp"
#include "protocol/lcm/channels.hpp"

namespace pumptherm::daemon {
namespace {

static_assert(kClearKeyBytes == crypto_auth_KEYBYTES, "the shared key is a crypto_auth key");
static_assert(crypto_auth_BYTES == 32, "alarm_clear_t.tag holds a crypto_auth tag");

/// The signed bytes (docs/lcm.md, "Signed bytes"): a domain string naming the type and its
/// version, a NUL, then each part in order, integers as 8 bytes big-endian and strings as a
/// 4-byte big-endian length and their bytes, so no two messages share a layout.
class Layout {
 public:
  explicit Layout(std::string_view domain) {
    bytes_.assign(domain.begin(), domain.end());
    bytes_.push_back(0);
  }
  Layout& Int(std::int64_t v) {
    const auto u = static_cast<std::uint64_t>(v);
    for (int shift = 56; shift >= 0; shift -= 8)
      bytes_.push_back(static_cast<std::uint8_t>(u >> shift));
    return *this;
  }
  Layout& Text(std::string_view s) {
    const auto n = static_cast<std::uint32_t>(s.size());
    for (int shift = 24; shift >= 0; shift -= 8)
      bytes_.push_back(static_cast<std::uint8_t>(n >> shift));
    bytes_.insert(bytes_.end(), s.begin(), s.end());
    return *this;
  }
  std::vector<std::uint8_t> Take() { return std::move(bytes_); }

 private:
  std::vector<std::uint8_t> bytes_;
};

void StartSodium() {
  static const int init = sodium_init();
  if (init < 0) throw std::runtime_error("libsodium cannot start (sodium_init)");
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

/// A string from outside, short enough for a log line and a map key.
std::string Clip(std::string_view s) {
  constexpr std::size_t kMax = 48;
  return s.size() <= kMax ? std::string(s) : std::string(s.substr(0, kMax)) + "...";
}

/// The file systemd handed over as credential `name` in `dir`, or "" when there is none (no
/// systemd, or its stand-in kNoCredential).
std::string CredentialCopy(const std::string& dir, const char* name,
                           const std::function<void(const std::string&)>& fail) {
  if (dir.empty()) return "";
  const std::string copy = dir + "/" + name;
  std::optional<std::string> text;
  try {
    text = ReadFileIfExists(copy);
  } catch (const std::system_error& e) {
    fail(e.what());
  }
  const bool real = text && *text != kNoCredential;
  if (text) sodium_memzero(text->data(), text->size());
  return real ? copy : "";
}

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
  sodium_memzero(text->data(), text->size());
  if (std::all_of(key.begin(), key.end(), [](std::uint8_t b) { return b == 0; }))
    throw std::runtime_error(fmt::format("{} is all zero bytes: not a key", path));
  return key;
}

std::string CredentialsDirectory() {
  const char* dir = std::getenv("CREDENTIALS_DIRECTORY");
  return dir ? dir : "";
}

std::optional<ClearKey> LoadConfiguredClearKey(const DaemonConfig& config,
                                               const std::string& credentials_dir) {
  const ClearAuthConfig& c = config.clear_auth;
  if (c.key_file.empty() || !c.allow_shared_key) return std::nullopt;
  const std::function<void(const std::string&)> fail = [&](const std::string& what) {
    throw ConfigError(
        fmt::format("{}:{}: key 'alarms.clear_key_file': {}", config.source, c.line, what));
  };
  if (const std::string problem = ClearKeyFileProblem(c.key_file, c.key_group); !problem.empty())
    fail(problem);
  // Under the shipped unit, systemd (as root) hands the file over as a credential: the
  // service's dynamic user is not in the operators' group.
  const std::string copy = CredentialCopy(credentials_dir, kClearKeyCredential, fail);
  try {
    return ReadClearKeyFile(copy.empty() ? c.key_file : copy);
  } catch (const std::runtime_error& e) {
    fail(e.what());
  }
  return std::nullopt;
}

std::optional<SigningKey> LoadConfiguredGatewayKey(const DaemonConfig& config,
                                                   const std::string& credentials_dir) {
  const GatewayConfig& g = config.gateway;
  if (g.signing_key_file.empty()) return std::nullopt;
  const std::function<void(const std::string&)> fail = [&](const std::string& what) {
    throw ConfigError(fmt::format("{}:{}: key 'gateway.signing_key_file': {}", config.source,
                                  g.signing_key_line, what));
  };
  if (const std::string problem = SecretKeyFileProblem(g.signing_key_file, KeyOwner::kCallerOrRoot);
      !problem.empty()) {
    fail(problem);
  }
  const std::string copy = CredentialCopy(credentials_dir, kGatewayKeyCredential, fail);
  try {
    return ReadSecretKeyFile(copy.empty() ? g.signing_key_file : copy);
  } catch (const std::runtime_error& e) {
    fail(e.what());
  }
  return std::nullopt;
}

std::vector<std::uint8_t> SignedBytes(const pumptherm::alarm_clear_t& m, std::string_view prefix) {
  Layout in("pumptherm.alarm_clear_t.2");
  in.Text(prefix)
      .Text(m.gateway)
      .Text(m.pump)
      .Text(m.node)
      .Text(m.key_id)
      .Text(m.comment)
      .Int(m.utime)
      .Int(m.counter);
  return in.Take();
}

std::vector<std::uint8_t> SignedBytes(const pumptherm::alarm_clear_reply_t& m,
                                      std::string_view prefix) {
  Layout in("pumptherm.alarm_clear_reply_t.2");
  in.Text(prefix)
      .Text(m.gateway)
      .Text(m.pump)
      .Text(m.key_id)
      .Int(m.counter)
      .Int(m.utime)
      .Int(m.result)
      .Text(m.reason)
      .Int(m.last_counter)
      .Int(m.trip_latched ? 1 : 0);
  return in.Take();
}

void SignCommand(const SigningKey& op, const PublicKey& gateway, std::string_view prefix,
                 pumptherm::alarm_clear_t& m) {
  m.key_id = op.key_id();
  const std::vector<std::uint8_t> bytes = SignedBytes(m, prefix);
  const auto tag = Tag(op.OperatorTagKey(gateway), bytes);
  std::memcpy(m.tag, tag.data(), tag.size());
  const Signature sig = op.Sign(bytes);
  std::memcpy(m.signature, sig.data(), sig.size());
}

void SignCommandShared(const ClearKey& key, const std::string& source, std::string_view prefix,
                       pumptherm::alarm_clear_t& m) {
  StartSodium();
  m.key_id = std::string(kSharedKeyIdPrefix) + source;
  const std::vector<std::uint8_t> bytes = SignedBytes(m, prefix);
  crypto_auth(m.tag, bytes.data(), bytes.size(), key.data());
  std::memset(m.signature, 0, sizeof m.signature);
}

void SignReply(const SigningKey& gateway, std::string_view prefix,
               pumptherm::alarm_clear_reply_t& r) {
  const Signature sig = gateway.Sign(SignedBytes(r, prefix));
  std::memcpy(r.signature, sig.data(), sig.size());
}

bool VerifyReply(const PublicKey& gateway, std::string_view prefix,
                 const pumptherm::alarm_clear_reply_t& r) {
  return VerifySignature(gateway, SignedBytes(r, prefix), r.signature);
}

ClearExchange SendClear(lcm::LCM& lcm, std::string_view prefix, const PublicKey& gateway,
                        const pumptherm::alarm_clear_t& m, double timeout_s) {
  using lcm_channels::PumpChannel;
  using lcm_channels::PumpChannelName;
  struct Listener {
    const PublicKey& gateway;
    std::string_view prefix;
    const pumptherm::alarm_clear_t& command;
    ClearExchange out;
    void On(const lcm::ReceiveBuffer* rbuf, const std::string&) {
      pumptherm::alarm_clear_reply_t r{};
      const int size = static_cast<int>(rbuf->data_size);
      if (r.decode(rbuf->data, 0, size) != size) return;
      if (r.counter != command.counter || r.key_id != command.key_id) return;
      if (VerifyReply(gateway, prefix, r)) {
        out.reply = r;
      } else {
        ++out.untrusted_replies;
        out.untrusted_reason = r.reason;
      }
    }
  } listener{gateway, prefix, m, {}};
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

ClearAuthenticator::ClearAuthenticator(std::string gateway, std::string prefix, double window_s)
    : gateway_(std::move(gateway)),
      prefix_(std::move(prefix)),
      window_us_(static_cast<std::int64_t>(window_s * 1e6)) {}

void ClearAuthenticator::SetGatewayKey(const SigningKey& key) {
  gateway_key_ = key;
  for (auto& [id, k] : keys_) k.tag_key = key.GatewayTagKey(k.op.public_key);
}

void ClearAuthenticator::AddOperator(const ClearOperator& op) {
  const std::string id = KeyId(op.public_key);
  if (keys_.count(id)) {
    throw std::invalid_argument(
        fmt::format("the key of '{}' is listed twice (key {})", op.name, id));
  }
  KnownKey k{op, {}};
  if (gateway_key_) k.tag_key = gateway_key_->GatewayTagKey(op.public_key);
  keys_.emplace(id, k);
}

void ClearAuthenticator::SetSharedKey(const ClearKey& key, std::vector<std::string> sources) {
  shared_key_ = key;
  shared_sources_ = std::move(sources);
}

bool ClearAuthenticator::Fresh(const pumptherm::alarm_clear_t& m, ClearCheckResult& r) const {
  if (m.utime <= refused_up_to_us_) {
    r.check = ClearCheck::kReplayed;
    r.reason = "signed before the gateway lost its clear counters (a replay?)";
    return false;
  }
  const std::int64_t last = last_counter(m.pump, m.key_id);
  if (m.counter > last) return true;
  r.check = ClearCheck::kReplayed;
  r.reason = fmt::format(
      "counter {} is not above the last accepted {} (a replay, or the sender's clock went back)",
      m.counter, last);
  return false;
}

bool ClearAuthenticator::InWindow(const pumptherm::alarm_clear_t& m, std::int64_t now_us,
                                  ClearCheckResult& r) const {
  // Written so that no subtraction can overflow, whatever utime holds.
  const bool too_old = m.utime < now_us && now_us - window_us_ > m.utime;
  const bool too_new = m.utime > now_us && m.utime - window_us_ > now_us;
  if (!too_old && !too_new) return true;
  r.check = ClearCheck::kOutsideWindow;
  r.reason = fmt::format("its time is {:.1f} s from the gateway's clock (window {:.0f} s)",
                         (static_cast<double>(m.utime) - static_cast<double>(now_us)) * 1e-6,
                         static_cast<double>(window_us_) * 1e-6);
  return false;
}

ClearCheckResult ClearAuthenticator::CheckShared(const pumptherm::alarm_clear_t& m,
                                                 const std::vector<std::uint8_t>& bytes,
                                                 std::int64_t now_us) const {
  ClearCheckResult r;
  const std::string source = m.key_id.substr(kSharedKeyIdPrefix.size());
  r.source = Clip(m.key_id);
  if (!shared_key_) {
    r.check = ClearCheck::kUnknownKey;
    r.reason = "a shared-key command, and that scheme is off (alarms.clear_allow_shared_key)";
    return r;
  }
  if (crypto_auth_verify(m.tag, bytes.data(), bytes.size(), shared_key_->data()) != 0) {
    r.check = ClearCheck::kBadTag;
    r.reason = "no or a wrong authentication tag";
    return r;
  }
  if (std::find(shared_sources_.begin(), shared_sources_.end(), source) == shared_sources_.end()) {
    r.check = ClearCheck::kUnknownKey;
    r.reason = fmt::format("source '{}' is not in alarms.clear_lcm_sources", Clip(source));
    return r;
  }
  if (!Fresh(m, r) || !InWindow(m, now_us, r)) return r;
  r.check = ClearCheck::kPassed;
  r.reason = "shared key";
  return r;
}

ClearCheckResult ClearAuthenticator::Check(const pumptherm::alarm_clear_t& m,
                                           std::int64_t now_us) const {
  StartSodium();
  ClearCheckResult r;
  r.source = fmt::format("key {} (unknown)", Clip(m.key_id));
  if (!gateway_key_) {
    r.check = ClearCheck::kNoGatewayKey;
    r.reason = "the gateway has no signing key (gateway.signing_key_file): LCM clears are off";
    return r;
  }
  if (m.gateway != gateway_) {
    r.check = ClearCheck::kOtherGateway;
    r.reason =
        fmt::format("it is for gateway '{}', not this one ('{}')", Clip(m.gateway), gateway_);
    return r;
  }
  const std::vector<std::uint8_t> bytes = SignedBytes(m, prefix_);
  if (m.key_id.rfind(kSharedKeyIdPrefix, 0) == 0) return CheckShared(m, bytes, now_us);
  const auto it = keys_.find(m.key_id);
  if (it == keys_.end()) {
    r.check = ClearCheck::kUnknownKey;
    r.reason = "its key is not in alarms.clear_operators";
    return r;
  }
  const KnownKey& k = it->second;
  r.source = fmt::format("{} (key {})", k.op.name, it->first);
  if (k.op.revoked) {
    r.check = ClearCheck::kRevokedKey;
    r.reason = "the key is revoked (alarms.clear_operators)";
    return r;
  }
  if (!VerifyTag(k.tag_key, bytes, m.tag)) {
    r.check = ClearCheck::kBadTag;
    r.reason = "no or a wrong tag (forged)";
    return r;
  }
  if (!Fresh(m, r)) return r;
  if (!VerifySignature(k.op.public_key, bytes, m.signature)) {
    r.check = ClearCheck::kBadSignature;
    r.reason = "the tag holds but the signature does not";
    return r;
  }
  if (!InWindow(m, now_us, r)) return r;
  r.check = ClearCheck::kPassed;
  r.reason = "signed";
  return r;
}

void ClearAuthenticator::Take(const pumptherm::alarm_clear_t& m) {
  std::int64_t& last = counters_[m.pump][m.key_id];
  last = std::max(last, m.counter);
}

std::int64_t ClearAuthenticator::last_counter(const std::string& pump,
                                              const std::string& key_id) const {
  const auto p = counters_.find(pump);
  if (p == counters_.end()) return 0;
  const auto k = p->second.find(key_id);
  return k == p->second.end() ? 0 : k->second;
}

void ClearAuthenticator::MergeCounters(const Counters& counters) {
  for (const auto& [pump, keys] : counters) {
    for (const auto& [key, counter] : keys) {
      std::int64_t& last = counters_[pump][key];
      last = std::max(last, counter);
    }
  }
}

void ClearAuthenticator::RefuseSignedUpTo(std::int64_t utime) {
  refused_up_to_us_ = std::max(refused_up_to_us_, utime);
}

pumptherm::alarm_clear_reply_t ClearAuthenticator::Reply(const pumptherm::alarm_clear_t& m,
                                                         std::int8_t result,
                                                         const std::string& reason,
                                                         bool trip_latched,
                                                         std::int64_t now_us) const {
  pumptherm::alarm_clear_reply_t r;
  r.utime = now_us;
  r.gateway = gateway_;
  r.pump = m.pump;
  r.key_id = m.key_id;
  r.counter = m.counter;
  r.result = result;
  r.reason = reason;
  r.last_counter = last_counter(m.pump, m.key_id);
  r.trip_latched = trip_latched;
  std::memset(r.signature, 0, sizeof r.signature);
  if (gateway_key_) SignReply(*gateway_key_, prefix_, r);
  return r;
}

}  // namespace pumptherm::daemon
