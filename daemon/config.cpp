#include "daemon/config.hpp"

#include <fmt/format.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>
#include <toml++/toml.h>

namespace pumptherm::daemon {
namespace {

/// Reads a table's keys, remembering which were used, so unknown keys (typos) are reported.
class TableReader {
 public:
  TableReader(const toml::table& table, std::string path, const std::string& source)
      : table_(table), path_(std::move(path)), source_(source) {}

  [[noreturn]] void Fail(const toml::node* node, std::string_view key, std::string_view what) const {
    const auto line = node ? node->source().begin.line : table_.source().begin.line;
    throw ConfigError(fmt::format("{}:{}: key '{}': {}", source_, line, Join(key), what));
  }

  std::string Join(std::string_view key) const {
    return path_.empty() ? std::string(key) : fmt::format("{}.{}", path_, key);
  }

  const toml::node* Get(std::string_view key) {
    used_.emplace_back(key);
    return table_.get(key);
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
    if (!std::isfinite(v)) Fail(n, key, "expected a finite number");
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
  TableReader top(root, "", source);

  if (const toml::node* g = top.Get("gateway")) {
    const toml::table* t = g->as_table();
    if (!t) top.Fail(g, "gateway", "expected a table [gateway]");
    TableReader r(*t, "gateway", source);
    const std::string default_name = config.gateway.name;
    config.gateway.name = r.String("name", &default_name);
    config.gateway.heartbeat_id =
        static_cast<std::uint32_t>(r.Integer("heartbeat_id", config.gateway.heartbeat_id, 0, 0x7FF));
    config.gateway.heartbeat_period_s =
        r.Number("heartbeat_period_s", config.gateway.heartbeat_period_s, 0.0, 3600.0);
    if (config.gateway.heartbeat_period_s > 0.0 && config.gateway.heartbeat_period_s < 0.01) {
      r.Fail(t->get("heartbeat_period_s"), "heartbeat_period_s", "below 0.01 s (100 Hz)");
    }
    config.gateway.status_period_s =
        r.Number("status_period_s", config.gateway.status_period_s, 0.1, 3600.0);
    r.RejectUnknown();
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
      r.RejectUnknown();
      config.interfaces.push_back(std::move(iface));
    }
  }
  top.RejectUnknown();
  return config;
}

DaemonConfig LoadConfig(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ConfigError(fmt::format("{}: cannot open: {}", path, std::strerror(errno)));
  std::ostringstream ss;
  ss << in.rdbuf();
  return ParseConfig(ss.str(), path);
}

}  // namespace pumptherm::daemon
