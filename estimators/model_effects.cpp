#include "estimators/model_effects.hpp"

#include <fmt/core.h>
#include <toml++/toml.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <sstream>
#include <stdexcept>

#include "estimators/thermal_model.hpp"

namespace pumptherm::estimators {
namespace {

bool IsBoundary(std::string_view name) { return name == "ambient" || name == "coolant"; }

toml::table ParseOrThrow(std::string_view text, const std::string& source) {
  try {
    return toml::parse(text, source);
  } catch (const toml::parse_error& e) {
    throw ThermalModelError(
        fmt::format("{}:{}: {}", source, e.source().begin.line, e.description()));
  }
}

/// The value of a numeric key as expression text: a number printed exactly, an expression in
/// parentheses.
std::string ExpressionOf(const toml::node* n, const std::string& what) {
  if (n == nullptr) throw ThermalModelError(fmt::format("{}: missing", what));
  if (auto s = n->value<std::string>()) return "(" + *s + ")";
  if (auto d = n->value<double>()) return fmt::format("{}", *d);
  throw ThermalModelError(fmt::format("{}: not a number or expression", what));
}

std::pair<std::string, std::string> Ends(const toml::table& edge) {
  const toml::array* b = edge["between"].as_array();
  if (b == nullptr || b->size() != 2) return {};
  return {b->get(0)->value_or(std::string{}), b->get(1)->value_or(std::string{})};
}

double NumberOr(const toml::node* n, double fallback) {
  if (n == nullptr) return fallback;
  if (auto d = n->value<double>()) return *d;
  return std::nan("");  // an expression: not known without evaluation
}

}  // namespace

const std::vector<EffectSpec>& EffectVocabulary() {
  static const std::vector<EffectSpec> kVocabulary{
      {"frame_thermal_mass",
       false,
       "heat capacity coupled to the frame that the model lacks (a mounting plate, a flange)",
       {{"frame_extra_capacity_J_per_K", 0.0, -0.9e6, 1e6, 1000.0}}},
      {"frame_ambient_resistance",
       false,
       "the frame's cooling to its boundary mis-estimated",
       {{"frame_resistance_scale", 1.0, 0.05, 20.0, 0.2}}},
      {"speed_dependent_cooling",
       false,
       "frame cooling that grows with speed (forced convection)",
       {{"cooling_speed_gain_per_krpm", 0.0, -0.9, 50.0, 0.2}}},
      {"winding_conductance",
       false,
       "the slot to end-winding conduction path wrong (Saheba 2010's k_c)",
       {{"winding_resistance_scale", 1.0, 0.01, 100.0, 1.0}}},
      {"copper_temperature_coefficient",
       false,
       "the copper resistance's temperature dependence missing or wrong",
       {{"copper_alpha_delta_per_K", 0.0, -0.01, 0.01, 0.001}}},
      {"iron_loss_scale",
       false,
       "iron loss mis-scaled",
       {{"iron_loss_scale", 1.0, 0.0, 20.0, 0.3}}},
      {"rotor_loss",
       false,
       "an extra rotor loss growing with the square of speed (eddy currents in magnets, sleeve)",
       {{"rotor_loss_W_per_krpm2", 0.0, -1e6, 1e6, 1.0}}},
      {"sensor_lag",
       true,
       "the sensor's own thermal lag",
       {{"sensor_lag_s", 0.0, 0.0, 3600.0, 30.0}}},
      {"sensor_offset",
       true,
       "a constant offset of the sensor",
       {{"sensor_offset_K", 0.0, -50.0, 50.0, 1.0}}},
  };
  return kVocabulary;
}

const EffectSpec* FindEffect(std::string_view name) {
  for (const EffectSpec& e : EffectVocabulary())
    if (e.name == name) return &e;
  return nullptr;
}

EffectTargets FindEffectTargets(std::string_view toml_text, const std::string& source) {
  const toml::table root = ParseOrThrow(toml_text, source);
  EffectTargets t;
  std::vector<std::string> capacitive;
  if (const toml::array* nodes = root["node"].as_array()) {
    for (const toml::node& nv : *nodes) {
      const toml::table* nt = nv.as_table();
      if (nt == nullptr) continue;
      const std::string name = (*nt)["name"].value_or(std::string{});
      const double c = NumberOr(nt->get("capacity_J_per_K"), 0.0);
      if (!(c == 0.0)) capacitive.push_back(name);
    }
  }
  auto has = [&](const std::string& n) {
    return std::find(capacitive.begin(), capacitive.end(), n) != capacitive.end();
  };
  for (const char* n : {"rotor", "pm", "magnet"})
    if (t.rotor.empty() && has(n)) t.rotor = n;
  for (const std::string& n : capacitive)
    if (t.rotor.empty() && n.find("rotor") != std::string::npos) t.rotor = n;

  const toml::array* edges = root["edge"].as_array();
  if (has("frame")) t.frame = "frame";
  if (t.frame.empty() && edges != nullptr) {
    for (const toml::node& ev : *edges) {
      const toml::table* et = ev.as_table();
      if (et == nullptr) continue;
      auto [a, b] = Ends(*et);
      if (IsBoundary(a)) std::swap(a, b);
      if (IsBoundary(b) && has(a) && a != t.rotor) {
        t.frame = a;
        break;
      }
    }
  }
  std::vector<std::string> winding;
  if (const toml::array* losses = root["loss"].as_array()) {
    int i = 0;
    for (const toml::node& lv : *losses) {
      const toml::table* lt = lv.as_table();
      if (lt != nullptr) {
        const std::string name = (*lt)["name"].value_or(std::string{});
        if (name.rfind("iron", 0) == 0) t.iron_losses.push_back(i);
        const toml::array* tn = (*lt)["temperature_nodes"].as_array();
        double alpha = NumberOr(lt->get("temperature_coefficient_per_K"), 0.0);
        // An expression that is a parameter's name takes that parameter's value; any other
        // expression counts as copper unless it starts with a minus sign.
        const std::string alpha_text =
            (*lt)["temperature_coefficient_per_K"].value_or(std::string{});
        if (std::isnan(alpha))
          alpha = NumberOr(root["parameters"][alpha_text].node(), std::nan(""));
        const bool positive = std::isnan(alpha) ? alpha_text.rfind("-", 0) != 0 : alpha > 0.0;
        if (tn != nullptr && !tn->empty() && positive && name.rfind("iron", 0) != 0) {
          t.copper_losses.push_back(i);
          for (const toml::node& w : *tn) winding.push_back(w.value_or(std::string{}));
        }
      }
      ++i;
    }
  }
  if (edges != nullptr) {
    int i = 0;
    for (const toml::node& ev : *edges) {
      if (const toml::table* et = ev.as_table()) {
        auto [a, b] = Ends(*et);
        if (IsBoundary(a)) std::swap(a, b);
        if (!t.frame.empty() && a == t.frame && IsBoundary(b)) t.frame_edges.push_back(i);
        if (IsBoundary(b) && !IsBoundary(a)) {
          t.cooling_edges.push_back(i);
          if (t.cooled.find(a) == std::string::npos) t.cooled += (t.cooled.empty() ? "" : ", ") + a;
        }
        const bool wa = std::find(winding.begin(), winding.end(), a) != winding.end();
        const bool wb = std::find(winding.begin(), winding.end(), b) != winding.end();
        if (wa && wb && a != b && t.winding_edge < 0) t.winding_edge = i;
      }
      ++i;
    }
  }
  return t;
}

std::string EffectNotApplicable(const EffectSpec& effect, const EffectTargets& t) {
  const std::string& n = effect.name;
  if (n == "frame_thermal_mass" && t.frame.empty()) return "no frame node";
  if (n == "frame_ambient_resistance" && t.frame_edges.empty())
    return "no edge between the frame and a boundary";
  if (n == "speed_dependent_cooling" && t.cooling_edges.empty()) return "no edge to a boundary";
  if (n == "winding_conductance" && t.winding_edge < 0)
    return "no edge between two winding (copper-loss temperature) nodes";
  if (n == "copper_temperature_coefficient" && t.copper_losses.empty())
    return "no temperature-dependent copper loss";
  if (n == "iron_loss_scale" && t.iron_losses.empty()) return "no loss named iron*";
  if (n == "rotor_loss" && t.rotor.empty()) return "no rotor node";
  return {};
}

std::string ApplyModelEffects(std::string_view toml_text, const std::string& source,
                              const std::vector<Effect>& effects,
                              const std::string& table_directory) {
  toml::table root = ParseOrThrow(toml_text, source);
  if (toml::array* tables = root["table"].as_array();
      tables != nullptr && !table_directory.empty()) {
    for (toml::node& tv : *tables) {
      toml::table* tt = tv.as_table();
      if (tt == nullptr) continue;
      const std::string file = (*tt)["file"].value_or(std::string{});
      if (!file.empty() && file.front() != '/')
        tt->insert_or_assign("file", table_directory + "/" + file);
    }
  }
  const EffectTargets t = FindEffectTargets(toml_text, source);
  if (!root.contains("parameters")) root.insert("parameters", toml::table{});
  toml::table& params = *root["parameters"].as_table();
  toml::array* edges = root["edge"].as_array();
  toml::array* losses = root["loss"].as_array();
  toml::array* nodes = root["node"].as_array();

  auto add_param = [&](const std::string& name, double v) {
    if (params.contains(name))
      throw ThermalModelError(
          fmt::format("{}: parameter {} already exists (effect added twice?)", source, name));
    params.insert(name, v);
  };
  auto edit = [&](toml::table& tbl, const char* key, const std::string& what,
                  const std::function<std::string(const std::string&)>& f) {
    const std::string old = ExpressionOf(tbl.get(key), what);
    tbl.insert_or_assign(key, f(old));
  };
  std::vector<std::string> names;
  for (const Effect& e : effects) {
    const EffectSpec* spec = FindEffect(e.name);
    if (spec == nullptr) throw ThermalModelError(fmt::format("unknown effect '{}'", e.name));
    if (e.values.size() != spec->parameters.size())
      throw ThermalModelError(fmt::format("effect {}: {} values, expected {}", e.name,
                                          e.values.size(), spec->parameters.size()));
    if (const std::string why = EffectNotApplicable(*spec, t); !why.empty())
      throw ThermalModelError(fmt::format("{}: effect {} does not apply: {}", source, e.name, why));
    const std::string& p = spec->parameters[0].name;
    const double v = e.values[0];
    names.push_back(spec->sensor ? e.name + "(" + e.node + ")" : e.name);
    if (spec->sensor) {
      add_param(p + "__" + e.node, v);
      continue;
    }
    add_param(p, v);
    if (e.name == "frame_thermal_mass") {
      for (toml::node& nv : *nodes) {
        toml::table& nt = *nv.as_table();
        if (nt["name"].value_or(std::string{}) == t.frame)
          edit(nt, "capacity_J_per_K", "node " + t.frame,
               [&](const std::string& old) { return old + " + " + p; });
      }
    } else if (e.name == "frame_ambient_resistance") {
      for (int i : t.frame_edges)
        edit(*edges->get(static_cast<std::size_t>(i))->as_table(), "resistance_K_per_W", "edge",
             [&](const std::string& old) { return p + " * " + old; });
    } else if (e.name == "speed_dependent_cooling") {
      for (int i : t.cooling_edges)
        edit(*edges->get(static_cast<std::size_t>(i))->as_table(), "resistance_K_per_W", "edge",
             [&](const std::string& old) {
               return old + " / max(1 + " + p + " * abs(speed_rpm) / 1000, 0.05)";
             });
    } else if (e.name == "winding_conductance") {
      edit(*edges->get(static_cast<std::size_t>(t.winding_edge))->as_table(), "resistance_K_per_W",
           "edge", [&](const std::string& old) { return p + " * " + old; });
    } else if (e.name == "copper_temperature_coefficient") {
      for (int i : t.copper_losses)
        edit(*losses->get(static_cast<std::size_t>(i))->as_table(), "temperature_coefficient_per_K",
             "loss", [&](const std::string& old) { return old + " + " + p; });
    } else if (e.name == "iron_loss_scale") {
      for (int i : t.iron_losses)
        edit(*losses->get(static_cast<std::size_t>(i))->as_table(), "power_W", "loss",
             [&](const std::string& old) { return p + " * " + old; });
    } else if (e.name == "rotor_loss") {
      if (losses == nullptr) {
        root.insert("loss", toml::array{});
        losses = root["loss"].as_array();
      }
      toml::table loss;
      loss.insert("name", "rotor_extra");
      loss.insert("power_W", p + " * (speed_rpm / 1000)^2");
      toml::table shares;
      shares.insert(t.rotor, 1.0);
      shares.is_inline(true);
      loss.insert("shares", std::move(shares));
      loss.insert("description", "added by the discrepancy workflow (rotor_loss)");
      losses->push_back(std::move(loss));
    }
  }
  if (toml::table* model = root["model"].as_table()) {
    std::string added;
    for (const auto& n : names) added += (added.empty() ? "" : ", ") + n;
    const std::string name = (*model)["name"].value_or(std::string{"model"});
    if (!names.empty()) model->insert_or_assign("name", name + "+effects");
    const std::string desc = (*model)["description"].value_or(std::string{});
    if (!names.empty()) model->insert_or_assign("description", desc + " | effects added: " + added);
  }
  std::ostringstream out;
  out << "# Written by the pumptherm discrepancy workflow (docs/discrepancy.md).\n"
      << "# Effects: ";
  for (std::size_t i = 0; i < names.size(); ++i) out << (i ? ", " : "") << names[i];
  out << (names.empty() ? "none" : "") << "\n\n" << root << "\n";
  return out.str();
}

void ApplySensorEffect(const Effect& effect, const std::vector<double>& time_s,
                       std::vector<double>& value) {
  if (effect.values.size() != 1)
    throw std::invalid_argument("sensor effect " + effect.name + ": expected one value");
  if (effect.name == "sensor_offset") {
    for (double& v : value) v += effect.values[0];
  } else if (effect.name == "sensor_lag") {
    const double tau = effect.values[0];
    if (!(tau > 0.0) || value.empty()) return;
    double prev_true = value[0];
    double y = value[0];
    for (std::size_t k = 1; k < value.size(); ++k) {
      const double dt = time_s[k] - time_s[k - 1];
      const double e = std::exp(-dt / tau);
      const double now = value[k];
      y = now + e * (y - prev_true) - (now - prev_true) * (tau / dt) * (1.0 - e);
      prev_true = now;
      value[k] = y;
    }
  }
}

std::string PhysicalReading(const Effect& e, const EffectTargets& t) {
  const double v = e.values.empty() ? 0.0 : e.values[0];
  if (e.name == "frame_thermal_mass")
    return fmt::format(
        "{:.2g} kJ/K {} heat capacity on the {}, about {:.1f} kg of steel "
        "(460 J/(kg K))",
        std::abs(v) / 1000.0, v >= 0 ? "more" : "less", t.frame, std::abs(v) / 460.0);
  if (e.name == "frame_ambient_resistance")
    return fmt::format(
        "the {}'s thermal resistance to its boundary is {:.3g} times the model's "
        "({} cooling)",
        t.frame, v, v < 1.0 ? "better" : "worse");
  if (e.name == "speed_dependent_cooling")
    return fmt::format(
        "the cooling conductance to the boundary ({}) grows by {:.3g} % per 1000 r/min", t.cooled,
        100.0 * v);
  if (e.name == "winding_conductance")
    return fmt::format("the slot to end-winding resistance is {:.3g} times the model's", v);
  if (e.name == "copper_temperature_coefficient")
    return fmt::format("the copper loss coefficient is {:+.3g} 1/K off (copper: 0.00393 1/K)", v);
  if (e.name == "iron_loss_scale")
    return fmt::format("the iron loss is {:.3g} times the model's", v);
  if (e.name == "rotor_loss")
    return fmt::format("{:.3g} W more loss in the {} at 1000 r/min (x (n/1000)^2)", v, t.rotor);
  if (e.name == "sensor_lag")
    return fmt::format("the {} sensor lags with a time constant of {:.3g} s", e.node, v);
  if (e.name == "sensor_offset") return fmt::format("the {} sensor reads {:+.3g} K off", e.node, v);
  return {};
}

}  // namespace pumptherm::estimators
