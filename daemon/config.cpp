#include "daemon/config.hpp"

#include <fmt/format.h>
#include <sys/stat.h>
#include <toml++/toml.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>

#include "daemon/resources.hpp"

namespace pumptherm::daemon {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

/// Reads a table's keys, remembering which were used, so unknown keys (typos) are reported.
class TableReader {
 public:
  TableReader(const toml::table& table, std::string path, const std::string& source)
      : table_(table), path_(std::move(path)), source_(source) {}

  [[noreturn]] void Fail(const toml::node* node, std::string_view key,
                         std::string_view what) const {
    const auto line = node ? node->source().begin.line : table_.source().begin.line;
    throw ConfigError(fmt::format("{}:{}: key '{}': {}", source_, line, Join(key), what));
  }

  std::string Join(std::string_view key) const {
    return path_.empty() ? std::string(key) : fmt::format("{}.{}", path_, key);
  }
  const std::string& path() const { return path_; }
  const toml::table& table() const { return table_; }

  const toml::node* Get(std::string_view key) {
    used_.emplace_back(key);
    return table_.get(key);
  }

  const toml::table* Table(std::string_view key) {
    const toml::node* n = Get(key);
    if (!n) return nullptr;
    const toml::table* t = n->as_table();
    if (!t) Fail(n, key, fmt::format("expected a table [{}]", Join(key)));
    return t;
  }

  double Number(std::string_view key, double fallback, double min, double max) {
    const toml::node* n = Get(key);
    if (!n) return fallback;
    double v = 0.0;
    if (auto i = n->as_integer()) {
      v = static_cast<double>(i->get());
    } else if (auto f = n->as_floating_point()) {
      v = f->get();
    } else {
      Fail(n, key, "expected a number");
    }
    if (std::isnan(v)) Fail(n, key, "expected a finite number");
    if (v < min || v > max) Fail(n, key, fmt::format("{} is outside [{}, {}]", v, min, max));
    return v;
  }

  std::int64_t Integer(std::string_view key, std::int64_t fallback, std::int64_t min,
                       std::int64_t max) {
    const toml::node* n = Get(key);
    if (!n) return fallback;
    auto i = n->as_integer();
    if (!i) Fail(n, key, "expected an integer");
    if (i->get() < min || i->get() > max) {
      Fail(n, key, fmt::format("{} is outside [{}, {}]", i->get(), min, max));
    }
    return i->get();
  }

  std::string String(std::string_view key, const std::string* fallback) {
    const toml::node* n = Get(key);
    if (!n) {
      if (fallback) return *fallback;
      Fail(nullptr, key, "missing (required)");
    }
    auto s = n->as_string();
    if (!s) Fail(n, key, "expected a string");
    return s->get();
  }

  std::vector<std::string> Strings(std::string_view key) {
    std::vector<std::string> out;
    const toml::node* n = Get(key);
    if (!n) return out;
    const toml::array* a = n->as_array();
    if (!a) Fail(n, key, "expected an array of strings");
    for (const auto& e : *a) {
      auto s = e.as_string();
      if (!s) Fail(&e, key, "expected an array of strings");
      out.push_back(s->get());
    }
    return out;
  }

  bool Bool(std::string_view key, bool fallback) {
    const toml::node* n = Get(key);
    if (!n) return fallback;
    auto b = n->as_boolean();
    if (!b) Fail(n, key, "expected true or false");
    return b->get();
  }

  /// Throws for any key that no reader asked for.
  void RejectUnknown() const {
    for (const auto& [k, v] : table_) {
      bool known = false;
      for (const auto& u : used_) known = known || (u == k.str());
      if (!known) Fail(&v, k.str(), "unknown key");
    }
  }

 private:
  const toml::table& table_;
  std::string path_;
  const std::string& source_;
  std::vector<std::string> used_;
};

/// alarms.clear_operators: an array of tables { name, public_key, revoked }.
void ReadClearOperators(TableReader& r, const std::string& source, ClearAuthConfig& c) {
  const toml::node* n = r.Get("clear_operators");
  if (!n) return;
  const toml::array* arr = n->as_array();
  if (!arr) r.Fail(n, "clear_operators", "expected an array of tables [[alarms.clear_operators]]");
  for (std::size_t i = 0; i < arr->size(); ++i) {
    const toml::table* t = (*arr)[i].as_table();
    if (!t) r.Fail(&(*arr)[i], "clear_operators", "expected a table { name, public_key }");
    TableReader opr(*t, r.Join(fmt::format("clear_operators[{}]", i)), source);
    ClearOperatorConfig op;
    op.line = static_cast<int>(t->source().begin.line);
    op.name = opr.String("name", nullptr);
    const bool printable = std::all_of(op.name.begin(), op.name.end(), [](char ch) {
      return static_cast<unsigned char>(ch) >= 0x20 && ch != 0x7f;
    });
    if (op.name.empty() || op.name.size() > 64 || !printable) {
      opr.Fail(t->get("name"), "name", "1 to 64 printable characters (who holds the key)");
    }
    std::string problem;
    const auto key = ParsePublicKey(opr.String("public_key", nullptr), &problem);
    if (!key) opr.Fail(t->get("public_key"), "public_key", problem);
    op.public_key = *key;
    op.revoked = opr.Bool("revoked", false);
    for (const auto& other : c.operators) {
      if (other.public_key == op.public_key) {
        opr.Fail(t->get("public_key"), "public_key",
                 fmt::format("the same key as '{}' (line {})", other.name, other.line));
      }
    }
    opr.RejectUnknown();
    c.operators.push_back(std::move(op));
  }
}

/// alarms.clear_operators, clear_window_s, and the shared key of the earlier scheme:
/// clear_key_file (relative to `base_dir`), clear_key_group, clear_allow_shared_key.
void ReadClearAuth(TableReader& r, const std::string& base_dir, const std::string& source,
                   ClearAuthConfig& c) {
  const std::string empty;
  ReadClearOperators(r, source, c);
  c.allow_shared_key = r.Bool("clear_allow_shared_key", false);
  c.key_file = r.String("clear_key_file", &empty);
  c.key_group = r.String("clear_key_group", &empty);
  c.window_s = r.Number("clear_window_s", c.window_s, 1.0, 3600.0);
  if (const toml::node* n = r.table().get("clear_key_file"))
    c.line = static_cast<int>(n->source().begin.line);
  if (!c.key_file.empty() && c.key_file[0] != '/') c.key_file = base_dir + "/" + c.key_file;
  if (!c.key_file.empty() && c.key_group.empty()) {
    r.Fail(r.table().get("clear_key_file"), "clear_key_group",
           "missing: name the group of operators that owns the clear key file");
  }
}

/// Whether `host` is this machine (a broker reached without leaving it).
bool LocalHost(const std::string& host) {
  return host == "localhost" || host == "::1" || host.rfind("127.", 0) == 0;
}

/// [mqtt]: the broker, the Sparkplug ids, TLS and credentials (docs/daemon.md, "[mqtt]").
void ReadMqtt(TableReader& r, const std::string& base_dir, MqttConfig& m) {
  const std::string empty;
  auto path = [&](std::string_view key, int& line) {
    if (const toml::node* n = r.table().get(key)) line = static_cast<int>(n->source().begin.line);
    std::string p = r.String(key, &empty);
    if (!p.empty() && p[0] != '/') p = base_dir + "/" + p;
    return p;
  };
  auto id = [&](std::string_view key, const std::string& fallback) {
    std::string v = r.String(key, &fallback);
    const bool ok = !v.empty() && v.size() <= 255 && v.find_first_of("/+#") == std::string::npos &&
                    std::all_of(v.begin(), v.end(), [](char c) {
                      return static_cast<unsigned char>(c) >= 0x20 && c != 0x7f;
                    });
    if (!ok && !(v.empty() && fallback.empty()))
      r.Fail(r.table().get(key), key, "1 to 255 printable characters without '/', '+' or '#'");
    return v;
  };
  m.enabled = true;
  m.line = static_cast<int>(r.table().source().begin.line);
  m.host = r.String("host", nullptr);
  if (m.host.empty()) r.Fail(r.table().get("host"), "host", "expected a host name or address");
  m.group_id = id("group_id", m.group_id);
  m.edge_node_id = id("edge_node_id", empty);
  m.ca_file = path("ca_file", m.ca_file_line);
  m.cert_file = path("cert_file", m.cert_file_line);
  m.key_file = path("key_file", m.key_file_line);
  m.username = r.String("username", &empty);
  m.password_file = path("password_file", m.password_file_line);
  m.allow_plaintext = r.Bool("allow_plaintext", false);
  m.keepalive_s = r.Number("keepalive_s", m.keepalive_s, 5.0, 3600.0);
  m.queue_steps = static_cast<std::size_t>(
      r.Integer("queue_steps", static_cast<std::int64_t>(m.queue_steps), 1, 65536));
  m.alarm_queue_steps = static_cast<std::size_t>(
      r.Integer("alarm_queue_steps", static_cast<std::int64_t>(m.alarm_queue_steps), 1, 65536));
  const bool tls = !m.ca_file.empty();
  m.port = static_cast<int>(r.Integer("port", tls ? 8883 : 1883, 1, 65535));
  if (m.cert_file.empty() != m.key_file.empty())
    r.Fail(r.table().get(m.cert_file.empty() ? "key_file" : "cert_file"),
           m.cert_file.empty() ? "cert_file" : "key_file",
           "missing: a client certificate needs its key, and the key its certificate");
  if (!tls && !m.cert_file.empty())
    r.Fail(r.table().get("cert_file"), "ca_file",
           "missing: a client certificate is only sent over TLS; name the broker's CA");
  if (!m.password_file.empty() && m.username.empty())
    r.Fail(r.table().get("password_file"), "username", "missing: a password needs a user name");
  if (!tls && !LocalHost(m.host) && !m.allow_plaintext) {
    r.Fail(r.table().get("host"), "host",
           fmt::format("'{}' is not this host and no ca_file is given: the connection would be "
                       "plain text (passwords and alarms readable on the network); give ca_file, "
                       "or say allow_plaintext = true",
                       m.host));
  }
  r.RejectUnknown();
}

}  // namespace

DaemonConfig ParseConfig(const std::string& text, const std::string& source) {
  toml::table root;
  try {
    root = toml::parse(text, source);
  } catch (const toml::parse_error& e) {
    throw ConfigError(fmt::format("{}:{}:{}: {}", source, e.source().begin.line,
                                  e.source().begin.column, e.description()));
  }
  DaemonConfig config;
  config.source = source;
  config.dbc.base_dir = DirectoryOf(source);
  TableReader top(root, "", source);

  // Alarm levels: a table of node -> { warning_degC, trip_degC }.
  auto read_levels = [&](TableReader& r, AlarmsConfig& a) {
    const toml::table* levels = r.Table("levels");
    if (!levels) return;
    for (const auto& [k, v] : *levels) {
      const std::string node(k.str());
      const toml::table* t = v.as_table();
      if (!t) r.Fail(&v, "levels." + node, "expected { warning_degC = ..., trip_degC = ... }");
      TableReader nr(*t, r.Join("levels." + node), source);
      LevelsConfig lc = a.levels.count(node) ? a.levels[node] : LevelsConfig{};
      lc.limits.warning_degC = nr.Number("warning_degC", lc.limits.warning_degC, -273.0, kInf);
      lc.limits.trip_degC = nr.Number("trip_degC", lc.limits.trip_degC, -273.0, kInf);
      // A trip level alone warns at the same level.
      if (!t->get("warning_degC") && t->get("trip_degC") &&
          !(lc.limits.warning_degC <= lc.limits.trip_degC)) {
        lc.limits.warning_degC = lc.limits.trip_degC;
      }
      if (lc.limits.trip_degC < lc.limits.warning_degC) {
        nr.Fail(t->get("trip_degC"), "trip_degC", "below warning_degC");
      }
      nr.RejectUnknown();
      lc.line = static_cast<int>(v.source().begin.line);
      lc.key = r.Join("levels." + node);
      a.levels[node] = lc;
    }
  };

  if (const toml::table* t = top.Table("gateway")) {
    TableReader r(*t, "gateway", source);
    GatewayConfig& g = config.gateway;
    const std::string default_name = g.name;
    g.name = r.String("name", &default_name);
    g.heartbeat_id =
        static_cast<std::uint32_t>(r.Integer("heartbeat_id", g.heartbeat_id, 0, 0x7FF));
    g.heartbeat_period_s = r.Number("heartbeat_period_s", g.heartbeat_period_s, 0.0, 3600.0);
    if (g.heartbeat_period_s > 0.0 && g.heartbeat_period_s < 0.01) {
      r.Fail(t->get("heartbeat_period_s"), "heartbeat_period_s", "below 0.01 s (100 Hz)");
    }
    g.status_period_s = r.Number("status_period_s", g.status_period_s, 0.1, 3600.0);
    g.thermal_period_s = r.Number("thermal_period_s", g.thermal_period_s, 0.01, 60.0);
    const std::string empty;
    g.state_directory = r.String("state_directory", &empty);
    g.state_save_period_s = r.Number("state_save_period_s", g.state_save_period_s, 1.0, 86400.0);
    g.test_hang_switch = r.Bool("test_hang_switch", false);
    g.test_state_write_pause_s = r.Number("test_state_write_pause_s", 0.0, 0.0, 5.0);
    g.test_safety_write_pause_s = r.Number("test_safety_write_pause_s", 0.0, 0.0, 5.0);
    g.signing_key_file = r.String("signing_key_file", &empty);
    if (const toml::node* n = t->get("signing_key_file"))
      g.signing_key_line = static_cast<int>(n->source().begin.line);
    if (!g.signing_key_file.empty() && g.signing_key_file[0] != '/')
      g.signing_key_file = config.dbc.base_dir + "/" + g.signing_key_file;
    const std::string latch = "latch";
    const std::string lost = r.String("lost_safety_state", &latch);
    if (lost != "latch" && lost != "warn") {
      r.Fail(t->get("lost_safety_state"), "lost_safety_state",
             fmt::format("'{}': expected \"latch\" or \"warn\"", lost));
    }
    g.lost_safety_state = lost == "warn" ? LostSafetyState::kWarn : LostSafetyState::kLatch;
    r.RejectUnknown();
  }

  if (const toml::table* t = top.Table("dbc")) {
    TableReader r(*t, "dbc", source);
    config.dbc.file = r.String("file", &config.dbc.file);
    config.dbc.mapping = r.String("mapping", &config.dbc.mapping);
    if (const toml::node* n = t->get("file"))
      config.dbc.file_line = static_cast<int>(n->source().begin.line);
    if (const toml::node* n = t->get("mapping"))
      config.dbc.mapping_line = static_cast<int>(n->source().begin.line);
    r.RejectUnknown();
  }

  if (const toml::table* t = top.Table("mqtt")) {
    TableReader r(*t, "mqtt", source);
    ReadMqtt(r, config.dbc.base_dir, config.mqtt);
  }
  if (const toml::table* t = top.Table("lcm")) {
    TableReader r(*t, "lcm", source);
    const std::string empty;
    config.lcm.url = r.String("url", &empty);
    config.lcm.channel_prefix = r.String("channel_prefix", &config.lcm.channel_prefix);
    if (config.lcm.channel_prefix.empty() ||
        config.lcm.channel_prefix.find_first_of(" \t/") != std::string::npos) {
      r.Fail(t->get("channel_prefix"), "channel_prefix",
             "must be non-empty, without spaces or '/'");
    }
    config.lcm.period_s = r.Number("period_s", config.lcm.period_s, 0.01, 3600.0);
    config.lcm.health_period_s =
        r.Number("health_period_s", config.lcm.health_period_s, 0.1, 3600.0);
    config.lcm.receive_interfaces = r.Strings("receive_interfaces");
    for (const std::string& name : config.lcm.receive_interfaces) {
      if (name.empty() || name.size() > 15 || name.find_first_of("/ \t") != std::string::npos) {
        r.Fail(t->get("receive_interfaces"), "receive_interfaces",
               fmt::format("'{}' is not an interface name", name));
      }
    }
    r.RejectUnknown();
  }

  if (const toml::table* t = top.Table("output_periods_s")) {
    for (const auto& [k, v] : *t) {
      TableReader r(*t, "output_periods_s", source);
      const std::string key(k.str());
      config.output_periods_s[key] = r.Number(key, 1.0, 0.001, 3600.0);
      config.output_period_lines[key] = static_cast<int>(v.source().begin.line);
    }
  }

  if (const toml::table* t = top.Table("alarms")) {
    TableReader r(*t, "alarms", source);
    AlarmsConfig a = config.alarms;
    auto& m = a.monitor;
    m.hysteresis_K = r.Number("hysteresis_K", m.hysteresis_K, 0.0, 100.0);
    m.hold_s = r.Number("hold_s", m.hold_s, 0.0, 3600.0);
    m.max_rise_K_per_min = r.Number("max_rise_K_per_min", m.max_rise_K_per_min, 0.0, kInf);
    m.rate_window_s = r.Number("rate_window_s", m.rate_window_s, 1.0, 3600.0);
    m.stale_after_s = r.Number("stale_after_s", m.stale_after_s, 0.05, 3600.0);
    m.sensor_min_degC = r.Number("sensor_min_degC", m.sensor_min_degC, -273.0, 1000.0);
    m.sensor_max_degC = r.Number("sensor_max_degC", m.sensor_max_degC, -273.0, 1000.0);
    if (m.sensor_max_degC <= m.sensor_min_degC) {
      r.Fail(t->get("sensor_max_degC"), "sensor_max_degC", "must be above sensor_min_degC");
    }
    m.stuck_after_s = r.Number("stuck_after_s", m.stuck_after_s, 1.0, 86400.0);
    m.stuck_model_move_K = r.Number("stuck_model_move_K", m.stuck_model_move_K, 0.0, 100.0);
    m.flat_after_s = r.Number("flat_after_s", m.flat_after_s, 0.0, 86400.0);
    m.max_step_K = r.Number("max_step_K", m.max_step_K, 0.1, 1000.0);
    m.jump_recover_s = r.Number("jump_recover_s", m.jump_recover_s, 0.0, 86400.0);
    m.nis_limit = r.Number("nis_limit", m.nis_limit, 0.0, kInf);
    m.max_sensor_offset_K = r.Number("max_sensor_offset_K", m.max_sensor_offset_K, 0.0, 100.0);
    m.disagree_hold_s = r.Number("disagree_hold_s", m.disagree_hold_s, 0.0, 86400.0);
    m.not_converged_grace_s =
        r.Number("not_converged_grace_s", m.not_converged_grace_s, 0.0, 86400.0);
    m.forecast_horizon_s = r.Number("forecast_horizon_s", m.forecast_horizon_s, 0.0, 86400.0);
    m.forecast_clear_s = r.Number("forecast_clear_s", m.forecast_clear_s, 0.0, 86400.0);
    m.sensor_fault_clear_s = r.Number("sensor_fault_clear_s", m.sensor_fault_clear_s, 0.0, 86400.0);
    m.silence_delay_s = r.Number("silence_delay_s", m.silence_delay_s, 0.0, 86400.0);
    m.trip_sd_factor = r.Number("trip_sd_factor", m.trip_sd_factor, 0.0, 10.0);
    m.warning_sd_factor = r.Number("warning_sd_factor", m.warning_sd_factor, 0.0, 10.0);
    a.clear_can_interfaces = r.Strings("clear_can_interfaces");
    a.clear_lcm_sources = r.Strings("clear_lcm_sources");
    ReadClearAuth(r, config.dbc.base_dir, source, config.clear_auth);
    read_levels(r, a);
    r.RejectUnknown();
    config.alarms = a;
  }

  if (const toml::node* c = top.Get("can")) {
    const toml::array* arr = c->as_array();
    if (!arr) top.Fail(c, "can", "expected an array of tables [[can]]");
    for (std::size_t i = 0; i < arr->size(); ++i) {
      const toml::table* t = (*arr)[i].as_table();
      if (!t) top.Fail(&(*arr)[i], "can", "expected a table [[can]]");
      TableReader r(*t, fmt::format("can[{}]", i), source);
      InterfaceConfig iface;
      iface.name = r.String("interface", nullptr);
      if (iface.name.empty() || iface.name.size() > 15 ||
          iface.name.find_first_of("/ \t") != std::string::npos) {
        r.Fail(t->get("interface"), "interface",
               fmt::format("'{}' is not an interface name (1 to 15 characters, no '/' or space)",
                           iface.name));
      }
      for (const auto& other : config.interfaces) {
        if (other.name == iface.name) {
          r.Fail(t->get("interface"), "interface", fmt::format("'{}' is listed twice", iface.name));
        }
      }
      iface.error_frames = r.Bool("error_frames", false);
      iface.rx_buffer_bytes =
          r.Integer("rx_buffer_bytes", iface.rx_buffer_bytes, 0, kMaxRxBufferBytes);
      if (iface.rx_buffer_bytes != 0 && iface.rx_buffer_bytes < kMinRxBufferBytes) {
        r.Fail(t->get("rx_buffer_bytes"), "rx_buffer_bytes",
               fmt::format("{} is below {} (0 keeps the kernel's default)", iface.rx_buffer_bytes,
                           kMinRxBufferBytes));
      }
      r.RejectUnknown();
      config.interfaces.push_back(std::move(iface));
    }
  }

  if (const toml::node* p = top.Get("pump")) {
    const toml::array* arr = p->as_array();
    if (!arr) top.Fail(p, "pump", "expected an array of tables [[pump]]");
    for (std::size_t i = 0; i < arr->size(); ++i) {
      const toml::table* t = (*arr)[i].as_table();
      if (!t) top.Fail(&(*arr)[i], "pump", "expected a table [[pump]]");
      TableReader r(*t, fmt::format("pump[{}]", i), source);
      PumpConfig pc;
      pc.line = static_cast<int>(t->source().begin.line);
      for (const auto& [k, v] : *t)
        pc.key_lines[std::string(k.str())] = static_cast<int>(v.source().begin.line);
      pc.name = r.String("name", nullptr);
      if (pc.name.empty() || pc.name.find_first_of(" \t/") != std::string::npos) {
        r.Fail(t->get("name"), "name",
               "must be non-empty, without spaces or '/' (it names LCM channels)");
      }
      pc.node_id = static_cast<std::uint32_t>(r.Integer("node_id", 0, 0, 65535));
      if (!t->get("node_id")) r.Fail(nullptr, "node_id", "missing (required)");
      const std::string first_interface =
          config.interfaces.empty() ? "" : config.interfaces[0].name;
      pc.interface = r.String("interface", &first_interface);
      pc.motor = r.String("motor", &pc.motor);
      pc.thermal_model = r.String("thermal_model", &pc.thermal_model);
      pc.measured_node = r.String("measured_node", &pc.measured_node);
      pc.fuse_winding = r.Bool("fuse_winding", pc.fuse_winding);
      pc.winding_sd_K = r.Number("winding_sd_K", pc.winding_sd_K, 0.01, 100.0);
      pc.magnet_node = r.String("magnet_node", &pc.magnet_node);
      pc.rotor_node = r.String("rotor_node", &pc.rotor_node);
      pc.magnet_min_sd_K = r.Number("magnet_min_sd_K", pc.magnet_min_sd_K, 0.01, 100.0);
      pc.magnet_max_winding_gain =
          r.Number("magnet_max_winding_gain", pc.magnet_max_winding_gain, 0.0, 10.0);
      pc.frame_sensor_lag_s = r.Number("frame_sensor_lag_s", pc.frame_sensor_lag_s, 0.0, 3600.0);
      pc.disturbance_states = r.Bool("disturbance_states", pc.disturbance_states);
      pc.disturbance_states_explicit = t->get("disturbance_states") != nullptr;
      pc.voltage_reading = r.Bool("voltage_reading", pc.voltage_reading);
      pc.model_losses_sd_rel = r.Number("model_losses_sd_rel", pc.model_losses_sd_rel, 0.01, 1.0);
      pc.alarms = config.alarms;
      if (const toml::table* at = r.Table("alarms")) {
        TableReader ar(*at, r.Join("alarms"), source);
        read_levels(ar, pc.alarms);
        ar.RejectUnknown();
      }
      for (const auto& other : config.pumps) {
        if (other.name == pc.name)
          r.Fail(t->get("name"), "name", fmt::format("pump '{}' is listed twice", pc.name));
        if (other.node_id == pc.node_id && other.interface == pc.interface) {
          r.Fail(t->get("node_id"), "node_id",
                 fmt::format("node {} on '{}' is already pump '{}'", pc.node_id, pc.interface,
                             other.name));
        }
      }
      r.RejectUnknown();
      config.pumps.push_back(std::move(pc));
    }
  }
  top.RejectUnknown();
  return config;
}

DaemonConfig LoadConfig(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode))
    throw ConfigError(fmt::format("{}: is a directory, not a configuration file", path));
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ConfigError(fmt::format("{}: cannot open: {}", path, std::strerror(errno)));
  std::ostringstream ss;
  ss << in.rdbuf();
  return ParseConfig(ss.str(), path);
}

std::string ConfigPermissionWarning(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return "";
  const bool group = (st.st_mode & S_IWGRP) != 0, others = (st.st_mode & S_IWOTH) != 0;
  if (!group && !others) return "";
  return fmt::format(
      "{} is writable by {} (mode {:04o}): whoever can write it sets the alarm "
      "levels and who may clear trips; make it 0644 or tighter",
      path,
      group && others ? "group and others"
      : group         ? "its group"
                      : "others",
      st.st_mode & 07777);
}

}  // namespace pumptherm::daemon
