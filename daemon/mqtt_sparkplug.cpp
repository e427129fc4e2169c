// Sparkplug B payloads from the published fields (daemon/mqtt_sparkplug.hpp).
#include "daemon/mqtt_sparkplug.hpp"

#include <array>
#include <bit>
#include <cmath>
#include <stdexcept>

#include "protocol/mapping.hpp"
#include "protocol/sparkplug_b.pb.h"

namespace pumptherm::daemon::mqtt {
namespace {

namespace pb = org::eclipse::tahu::protobuf;

constexpr std::string_view kNamespace = "spBv1.0";

/// The fields that exist only for the node-indexed CAN frame: a pump's nodes go by name here.
bool NodeIndexedOnly(const PublishedField& f) {
  return f.name == protocol::kNodeIndexKey || f.name == protocol::kNodeTempKey ||
         f.name == protocol::kNodeSdKey;
}

/// The published fields a device carries, in their declared order, into `out` (no allocation
/// once `out` holds them all; FillDeviceValues keeps its own).
template <typename F>
void ForEachDeviceField(F&& f) {
  for (const PublishedField& field : PublishedFields())
    if (!NodeIndexedOnly(field)) f(field);
}

/// Sets the metric's value from `v`; NaN is "not available": is_null, no value (spec 6.4.9).
void SetValue(pb::Payload::Metric& m, DataType type, double v) {
  if (std::isnan(v)) {
    m.set_is_null(true);
    return;
  }
  switch (type) {
    case DataType::kUInt32:
      m.set_int_value(static_cast<std::uint32_t>(v));
      break;
    case DataType::kInt64:
      m.set_long_value(static_cast<std::uint64_t>(static_cast<std::int64_t>(v)));
      break;
    case DataType::kBoolean:
      m.set_boolean_value(v != 0.0);
      break;
    case DataType::kDouble:
      m.set_double_value(v);
      break;
  }
}

/// Two values are the same when their bits are (NaN stays NaN: no change to send).
bool Same(double a, double b) {
  return std::bit_cast<std::uint64_t>(a) == std::bit_cast<std::uint64_t>(b);
}

std::string Serialize(const pb::Payload& p) {
  std::string out;
  p.SerializeToString(&out);
  return out;
}

}  // namespace

std::string_view MessageTypeName(MessageType type) {
  static constexpr std::array<std::string_view, 6> kNames{"NBIRTH", "NDEATH", "DBIRTH",
                                                          "DDEATH", "DDATA",  "NCMD"};
  return kNames.at(static_cast<std::size_t>(type));
}

bool ValidId(std::string_view id) {
  if (id.empty() || id.size() > 255) return false;
  for (const char c : id) {
    const auto u = static_cast<unsigned char>(c);
    if (c == '/' || c == '+' || c == '#' || u < 0x20 || u == 0x7f) return false;
  }
  return true;
}

std::string Topic(std::string_view group_id, MessageType type, std::string_view edge_node_id,
                  std::string_view device_id) {
  std::string t;
  t.reserve(kNamespace.size() + group_id.size() + edge_node_id.size() + device_id.size() + 12);
  t.append(kNamespace).append("/").append(group_id).append("/");
  t.append(MessageTypeName(type)).append("/").append(edge_node_id);
  if (!device_id.empty()) t.append("/").append(device_id);
  return t;
}

std::vector<MetricSpec> DeviceMetrics(std::span<const std::string> node_names) {
  std::vector<MetricSpec> out;
  ForEachDeviceField([&](const PublishedField& f) {
    out.push_back({std::string(f.name), std::string(f.unit),
                   f.csv.kind == CsvFormat::Kind::kWord ? DataType::kUInt32 : DataType::kDouble});
  });
  for (const std::string& n : node_names) {
    out.push_back({n + "_degC", "degC", DataType::kDouble});
    out.push_back({n + "_sd_K", "K", DataType::kDouble});
  }
  return out;
}

void FillDeviceValues(const FieldSource& source, std::span<double> out) {
  std::size_t k = 0;
  auto put = [&](double v) {
    if (k >= out.size()) throw std::out_of_range("mqtt: more metrics than values");
    out[k++] = v;
  };
  ForEachDeviceField([&](const PublishedField& f) { put(f.value(source)); });
  const estimators::PumpEstimate& e = *source.estimate;
  for (std::size_t n = 0; n < e.node_degC.size(); ++n) {
    put(e.node_degC[n]);
    put(n < e.node_sd_K.size() ? e.node_sd_K[n] : std::numeric_limits<double>::quiet_NaN());
  }
  if (k != out.size()) throw std::out_of_range("mqtt: fewer metrics than values");
}

bool RebirthRequested(std::string_view payload) {
  pb::Payload p;
  if (!p.ParseFromArray(payload.data(), static_cast<int>(payload.size()))) return false;
  for (const auto& m : p.metrics())
    if (m.name() == "Node Control/Rebirth" && m.has_boolean_value() && m.boolean_value())
      return true;
  return false;
}

std::uint64_t Alias(std::size_t device, std::size_t metric) {
  return (static_cast<std::uint64_t>(device + 1) << 32U) | static_cast<std::uint64_t>(metric);
}

Encoder::Encoder(std::vector<Device> devices)
    : devices_(std::move(devices)), sent_(devices_.size()) {}

std::uint64_t Encoder::NextSeq() {
  const std::uint64_t s = seq_;
  seq_ = (seq_ + 1) % 256;
  return s;
}

std::string Encoder::NodeBirth(std::uint64_t bd_seq, std::uint64_t time_ms) {
  seq_ = 0;
  for (auto& s : sent_) s.clear();
  pb::Payload p;
  p.set_timestamp(time_ms);
  p.set_seq(NextSeq());
  auto* bd = p.add_metrics();
  bd->set_name("bdSeq");
  bd->set_timestamp(time_ms);
  bd->set_datatype(static_cast<std::uint32_t>(DataType::kInt64));
  bd->set_long_value(bd_seq);
  auto* rebirth = p.add_metrics();
  rebirth->set_name("Node Control/Rebirth");
  rebirth->set_timestamp(time_ms);
  rebirth->set_datatype(static_cast<std::uint32_t>(DataType::kBoolean));
  rebirth->set_boolean_value(false);
  return Serialize(p);
}

std::string Encoder::NodeDeath(std::uint64_t bd_seq) {
  pb::Payload p;
  auto* bd = p.add_metrics();
  bd->set_name("bdSeq");
  bd->set_datatype(static_cast<std::uint32_t>(DataType::kInt64));
  bd->set_long_value(bd_seq);
  return Serialize(p);
}

std::string Encoder::DeviceBirth(std::size_t device, std::span<const double> values,
                                 std::uint64_t time_ms) {
  const Device& d = devices_.at(device);
  if (values.size() != d.metrics.size()) throw std::out_of_range("mqtt: DBIRTH value count");
  pb::Payload p;
  p.set_timestamp(time_ms);
  p.set_seq(NextSeq());
  for (std::size_t k = 0; k < d.metrics.size(); ++k) {
    const MetricSpec& spec = d.metrics[k];
    auto* m = p.add_metrics();
    m->set_name(spec.name);
    m->set_alias(Alias(device, k));
    m->set_timestamp(time_ms);
    m->set_datatype(static_cast<std::uint32_t>(spec.type));
    if (!spec.unit.empty()) {
      // Ignition's and Tahu's engineering-unit property; the name already carries the unit.
      auto* props = m->mutable_properties();
      props->add_keys("engUnit");
      auto* v = props->add_values();
      v->set_type(12);  // String
      v->set_string_value(spec.unit);
    }
    SetValue(*m, spec.type, values[k]);
  }
  sent_[device].assign(values.begin(), values.end());
  return Serialize(p);
}

std::string Encoder::DeviceData(std::size_t device, std::span<const double> values,
                                std::uint64_t time_ms, bool every_metric) {
  const Device& d = devices_.at(device);
  if (values.size() != d.metrics.size()) throw std::out_of_range("mqtt: DDATA value count");
  std::vector<double>& sent = sent_[device];
  if (sent.size() != values.size()) throw std::logic_error("mqtt: DDATA before the DBIRTH");
  pb::Payload p;
  for (std::size_t k = 0; k < values.size(); ++k) {
    if (!every_metric && Same(values[k], sent[k])) continue;
    auto* m = p.add_metrics();
    m->set_alias(Alias(device, k));
    m->set_timestamp(time_ms);
    m->set_datatype(static_cast<std::uint32_t>(d.metrics[k].type));
    SetValue(*m, d.metrics[k].type, values[k]);
    sent[k] = values[k];
  }
  if (p.metrics_size() == 0) return {};
  p.set_timestamp(time_ms);
  p.set_seq(NextSeq());
  return Serialize(p);
}

}  // namespace pumptherm::daemon::mqtt
