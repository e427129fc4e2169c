#include "protocol/dbc_writer.hpp"

#include <fmt/format.h>

#include <cmath>
#include <map>
#include <set>
#include <stdexcept>

namespace pumptherm::protocol {
namespace {

using Object = DbcAttributeDefinition::Object;
using Type = DbcAttributeDefinition::Type;

constexpr std::uint32_t kExtendedFlag = 0x80000000u;
/// The longest name Vector's tools write in a statement.
constexpr std::size_t kMaxShortName = 32;
/// A short name made for a long one: this many of its characters, '_' and 4 digits.
constexpr std::size_t kShortNameStem = 27;

bool IsNameChar(char c) {
  return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_';
}

/// A name a DBC statement can hold as it is: at most 32 characters of [A-Za-z0-9_] (names that
/// start with a digit are read by ParseDbc, cantools and canmatrix alike).
bool WritableAsIs(const std::string& name) {
  if (name.empty() || name.size() > kMaxShortName) return false;
  for (char c : name) {
    if (!IsNameChar(c)) return false;
  }
  return true;
}

std::string Quoted(std::string_view text) {
  std::string out = "\"";
  for (char c : text) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + '"';
}

/// Short names for one kind of object (nodes, messages, the signals of one message): a name
/// written as it is where it can be, else a short one (NameMaker::Short) with the long name as
/// an attribute.
class NameMaker {
 public:
  explicit NameMaker(const std::vector<std::string>& names) {
    for (const auto& n : names) {
      if (WritableAsIs(n)) taken_.insert(n);
    }
  }
  /// The name written in statements for `name`.
  std::string Short(const std::string& name) {
    if (WritableAsIs(name)) return name;
    if (const auto it = made_.find(name); it != made_.end()) return it->second;
    std::string stem;
    for (char c : name) {
      if (stem.size() == kShortNameStem) break;
      stem += IsNameChar(c) ? c : '_';
    }
    for (;; ++counter_) {
      const std::string candidate = fmt::format("{}_{:04d}", stem, counter_);
      if (taken_.insert(candidate).second) {
        made_[name] = candidate;
        ++counter_;
        return candidate;
      }
    }
  }
  /// Whether `name` needs a long-name attribute.
  static bool NeedsLongName(const std::string& name) { return !WritableAsIs(name); }

 private:
  std::set<std::string> taken_;
  std::map<std::string, std::string> made_;
  int counter_ = 0;
};

std::string RawId(const DbcMessage& m) {
  return std::to_string(m.extended ? (m.id | kExtendedFlag) : m.id);
}

const DbcAttributeDefinition* FindDefinition(const Dbc& dbc, std::string_view name) {
  for (const auto& d : dbc.attribute_definitions) {
    if (d.name == name) return &d;
  }
  return nullptr;
}

/// An attribute value as BA_ and BA_DEF_DEF_ write it: an ENUM's label as its index (as the
/// reader stores the index of BA_ as the label), integers of INT and HEX without a fraction.
std::string AttributeValue(const DbcAttributeDefinition* d, const DbcAttributeValue& v,
                           bool is_default) {
  if (const std::string* text = std::get_if<std::string>(&v)) {
    if (d != nullptr && d->type == Type::kEnum && !is_default) {
      for (std::size_t i = 0; i < d->enum_values.size(); ++i) {
        if (d->enum_values[i] == *text) return std::to_string(i);
      }
    }
    return Quoted(*text);
  }
  return DbcNumber(std::get<double>(v));
}

const char* ObjectKeyword(Object o) {
  switch (o) {
    case Object::kNetwork:
      return "";
    case Object::kNode:
      return "BU_ ";
    case Object::kMessage:
      return "BO_ ";
    case Object::kSignal:
      return "SG_ ";
    case Object::kEnvironment:
      return "EV_ ";
  }
  return "";
}

std::string Definition(const DbcAttributeDefinition& d) {
  std::string out = fmt::format("BA_DEF_ {}{} ", ObjectKeyword(d.object), Quoted(d.name));
  switch (d.type) {
    case Type::kInt:
      return out + fmt::format("INT {} {};", DbcNumber(d.minimum), DbcNumber(d.maximum));
    case Type::kHex:
      return out + fmt::format("HEX {} {};", DbcNumber(d.minimum), DbcNumber(d.maximum));
    case Type::kFloat:
      return out + fmt::format("FLOAT {} {};", DbcNumber(d.minimum), DbcNumber(d.maximum));
    case Type::kString:
      return out + "STRING ;";
    case Type::kEnum: {
      std::string values;
      for (const auto& v : d.enum_values) values += (values.empty() ? "" : ",") + Quoted(v);
      return out + "ENUM " + values + ";";
    }
  }
  return out + ";";
}

std::string ValueDescriptions(const std::map<std::int64_t, std::string>& values) {
  std::string out;
  for (const auto& [raw, label] : values) out += fmt::format(" {} {}", raw, Quoted(label));
  return out;
}

/// Whether signal `s` of `m` is multiplexed in the way an `mN` indicator alone says: by the
/// message's only top-level multiplexer, at one value.
bool SimpleMultiplexing(const DbcMessage& m, const DbcSignal& s) {
  if (s.multiplexer_ranges.size() != 1 ||
      s.multiplexer_ranges[0].low != s.multiplexer_ranges[0].high)
    return false;
  int top = 0;
  const DbcSignal* top_signal = nullptr;
  for (const auto& other : m.signals) {
    if (other.is_multiplexer && other.multiplexer_switch.empty()) {
      ++top;
      top_signal = &other;
    }
  }
  return top == 1 && top_signal->name == s.multiplexer_switch;
}

/// The text between a signal's name and its ':' ("", " M", " m3", " m3M").
std::string MuxIndicator(const DbcSignal& s) {
  if (s.multiplexer_switch.empty()) return s.is_multiplexer ? " M" : "";
  const std::uint64_t first = s.multiplexer_ranges.empty() ? 0 : s.multiplexer_ranges[0].low;
  return fmt::format(" m{}{}", first, s.is_multiplexer ? "M" : "");
}

/// Names as written: nodes, messages, and per message its signals.
struct ShortNames {
  std::map<std::string, std::string> nodes;
  std::vector<std::string> messages;
  std::vector<std::map<std::string, std::string>> signals;  // per message: name -> short
  bool long_nodes = false, long_messages = false, long_signals = false;

  std::string Node(const std::string& name) const {
    if (name.empty()) return "Vector__XXX";
    const auto it = nodes.find(name);
    return it == nodes.end() ? name : it->second;
  }
};

ShortNames MakeShortNames(const Dbc& dbc) {
  ShortNames n;
  std::vector<std::string> node_names = dbc.nodes;
  for (const auto& m : dbc.messages) {
    node_names.push_back(m.transmitter);
    for (const auto& s : m.signals)
      node_names.insert(node_names.end(), s.receivers.begin(), s.receivers.end());
  }
  NameMaker nodes(node_names);
  for (const auto& name : node_names) {
    if (name.empty()) continue;
    n.nodes[name] = nodes.Short(name);
    n.long_nodes = n.long_nodes || NameMaker::NeedsLongName(name);
  }
  std::vector<std::string> message_names;
  for (const auto& m : dbc.messages) message_names.push_back(m.name);
  NameMaker messages(message_names);
  for (const auto& m : dbc.messages) {
    if (m.name.empty()) throw std::invalid_argument("a message without a name");
    n.messages.push_back(messages.Short(m.name));
    n.long_messages = n.long_messages || NameMaker::NeedsLongName(m.name);
    std::vector<std::string> signal_names;
    for (const auto& s : m.signals) signal_names.push_back(s.name);
    NameMaker signals(signal_names);
    auto& map = n.signals.emplace_back();
    for (const auto& s : m.signals) {
      if (s.name.empty()) throw std::invalid_argument("a signal without a name in " + m.name);
      map[s.name] = signals.Short(s.name);
      n.long_signals = n.long_signals || NameMaker::NeedsLongName(s.name);
    }
  }
  return n;
}

void WriteMessages(const Dbc& dbc, const ShortNames& names, std::string& out) {
  for (std::size_t mi = 0; mi < dbc.messages.size(); ++mi) {
    const DbcMessage& m = dbc.messages[mi];
    out += fmt::format("BO_ {} {}: {} {}\n", RawId(m), names.messages[mi], m.size_bytes,
                       names.Node(m.transmitter));
    for (const auto& s : m.signals) {
      std::string receivers;
      for (const auto& r : s.receivers) receivers += (receivers.empty() ? "" : ",") + names.Node(r);
      if (receivers.empty()) receivers = "Vector__XXX";
      out += fmt::format(" SG_ {}{} : {}|{}@{}{} ({},{}) [{}|{}] {} {}\n",
                         names.signals[mi].at(s.name), MuxIndicator(s), s.start_bit, s.length_bits,
                         s.byte_order == ByteOrder::kLittleEndian ? 1 : 0, s.is_signed ? '-' : '+',
                         DbcNumber(s.factor), DbcNumber(s.offset), DbcNumber(s.minimum),
                         DbcNumber(s.maximum), Quoted(s.unit), receivers);
    }
    out += '\n';
  }
}

void WriteComments(const Dbc& dbc, const ShortNames& names, std::string& out) {
  if (!dbc.comment.empty()) out += fmt::format("CM_ {};\n", Quoted(dbc.comment));
  for (const auto& [node, text] : dbc.node_comments)
    out += fmt::format("CM_ BU_ {} {};\n", names.Node(node), Quoted(text));
  for (std::size_t mi = 0; mi < dbc.messages.size(); ++mi) {
    const DbcMessage& m = dbc.messages[mi];
    if (!m.comment.empty()) out += fmt::format("CM_ BO_ {} {};\n", RawId(m), Quoted(m.comment));
    for (const auto& s : m.signals) {
      if (!s.comment.empty())
        out += fmt::format("CM_ SG_ {} {} {};\n", RawId(m), names.signals[mi].at(s.name),
                           Quoted(s.comment));
    }
  }
}

/// BA_DEF_ and BA_DEF_DEF_ of the file, and those of the long names it needs and lacks.
void WriteDefinitions(const Dbc& dbc, const ShortNames& names, std::string& out) {
  std::vector<DbcAttributeDefinition> defs = dbc.attribute_definitions;
  auto need = [&](bool needed, const char* name, Object object) {
    if (!needed || FindDefinition(dbc, name) != nullptr) return;
    DbcAttributeDefinition d;
    d.name = name;
    d.object = object;
    d.type = Type::kString;
    d.default_value = std::string();
    defs.push_back(std::move(d));
  };
  need(names.long_nodes, "SystemNodeLongSymbol", Object::kNode);
  need(names.long_messages, "SystemMessageLongSymbol", Object::kMessage);
  need(names.long_signals, "SystemSignalLongSymbol", Object::kSignal);
  for (const auto& d : defs) out += Definition(d) + '\n';
  for (const auto& d : defs) {
    if (d.default_value)
      out += fmt::format("BA_DEF_DEF_ {} {};\n", Quoted(d.name),
                         AttributeValue(&d, *d.default_value, true));
  }
}

void WriteAttributes(const Dbc& dbc, const ShortNames& names, std::string& out) {
  auto value = [&](const std::string& name, const DbcAttributeValue& v) {
    return AttributeValue(FindDefinition(dbc, name), v, false);
  };
  for (const auto& [name, v] : dbc.network_attributes)
    out += fmt::format("BA_ {} {};\n", Quoted(name), value(name, v));
  for (const auto& [node, attributes] : dbc.node_attributes) {
    for (const auto& [name, v] : attributes)
      out += fmt::format("BA_ {} BU_ {} {};\n", Quoted(name), names.Node(node), value(name, v));
  }
  for (const auto& [node, short_name] : names.nodes) {
    if (NameMaker::NeedsLongName(node))
      out += fmt::format("BA_ \"SystemNodeLongSymbol\" BU_ {} {};\n", short_name, Quoted(node));
  }
  for (std::size_t mi = 0; mi < dbc.messages.size(); ++mi) {
    const DbcMessage& m = dbc.messages[mi];
    for (const auto& [name, v] : m.attributes)
      out += fmt::format("BA_ {} BO_ {} {};\n", Quoted(name), RawId(m), value(name, v));
    if (NameMaker::NeedsLongName(m.name))
      out += fmt::format("BA_ \"SystemMessageLongSymbol\" BO_ {} {};\n", RawId(m), Quoted(m.name));
    for (const auto& s : m.signals) {
      const std::string& short_name = names.signals[mi].at(s.name);
      for (const auto& [name, v] : s.attributes)
        out += fmt::format("BA_ {} SG_ {} {} {};\n", Quoted(name), RawId(m), short_name,
                           value(name, v));
      if (NameMaker::NeedsLongName(s.name))
        out += fmt::format("BA_ \"SystemSignalLongSymbol\" SG_ {} {} {};\n", RawId(m), short_name,
                           Quoted(s.name));
    }
  }
}

/// VAL_, SIG_VALTYPE_ and SG_MUL_VAL_: what the signals need after the attributes.
void WriteSignalTables(const Dbc& dbc, const ShortNames& names, std::string& out) {
  for (std::size_t mi = 0; mi < dbc.messages.size(); ++mi) {
    const DbcMessage& m = dbc.messages[mi];
    for (const auto& s : m.signals) {
      if (!s.value_descriptions.empty())
        out += fmt::format("VAL_ {} {}{} ;\n", RawId(m), names.signals[mi].at(s.name),
                           ValueDescriptions(s.value_descriptions));
    }
  }
  for (std::size_t mi = 0; mi < dbc.messages.size(); ++mi) {
    const DbcMessage& m = dbc.messages[mi];
    for (const auto& s : m.signals) {
      if (s.value_type == SignalValueType::kInteger) continue;
      out += fmt::format("SIG_VALTYPE_ {} {} : {};\n", RawId(m), names.signals[mi].at(s.name),
                         s.value_type == SignalValueType::kFloat32 ? 1 : 2);
    }
  }
  for (std::size_t mi = 0; mi < dbc.messages.size(); ++mi) {
    const DbcMessage& m = dbc.messages[mi];
    for (const auto& s : m.signals) {
      if (s.multiplexer_switch.empty() || SimpleMultiplexing(m, s)) continue;
      std::string ranges;
      for (const auto& r : s.multiplexer_ranges)
        ranges += fmt::format("{}{}-{}", ranges.empty() ? "" : ", ", r.low, r.high);
      out += fmt::format("SG_MUL_VAL_ {} {} {} {};\n", RawId(m), names.signals[mi].at(s.name),
                         names.signals[mi].at(s.multiplexer_switch), ranges);
    }
  }
}

}  // namespace

std::string DbcNumber(double v) {
  if (!std::isfinite(v)) throw std::invalid_argument("a DBC number must be finite");
  const std::string s = fmt::format("{}", v);  // the shortest text that reads back as v
  const std::size_t e = s.find_first_of("eE");
  if (e == std::string::npos) return s;
  const int exponent = std::stoi(s.substr(e + 1));
  std::string mantissa = s.substr(0, e);
  const bool negative = mantissa[0] == '-';
  if (negative) mantissa.erase(0, 1);
  const std::size_t dot = mantissa.find('.');
  std::string digits = mantissa;
  long point =
      dot == std::string::npos ? static_cast<long>(mantissa.size()) : static_cast<long>(dot);
  if (dot != std::string::npos) digits.erase(dot, 1);
  point += exponent;  // digits before the decimal point
  std::string out;
  if (point <= 0) {
    out = "0." + std::string(static_cast<std::size_t>(-point), '0') + digits;
  } else if (static_cast<std::size_t>(point) >= digits.size()) {
    out = digits + std::string(static_cast<std::size_t>(point) - digits.size(), '0');
  } else {
    out = digits.substr(0, static_cast<std::size_t>(point)) + "." +
          digits.substr(static_cast<std::size_t>(point));
  }
  return negative ? "-" + out : out;
}

std::string FormatDbc(const Dbc& dbc) {
  const ShortNames names = MakeShortNames(dbc);
  std::string out = fmt::format("VERSION {}\n\n", Quoted(dbc.version));
  out +=
      "NS_ :\n\tNS_DESC_\n\tCM_\n\tBA_DEF_\n\tBA_\n\tVAL_\n\tCAT_DEF_\n\tCAT_\n\tFILTER\n"
      "\tBA_DEF_DEF_\n\tEV_DATA_\n\tENVVAR_DATA_\n\tSGTYPE_\n\tSGTYPE_VAL_\n\tBA_DEF_SGTYPE_\n"
      "\tBA_SGTYPE_\n\tSIG_TYPE_REF_\n\tVAL_TABLE_\n\tSIG_GROUP_\n\tSIG_VALTYPE_\n"
      "\tSIGTYPE_VALTYPE_\n\tBO_TX_BU_\n\tBA_DEF_REL_\n\tBA_REL_\n\tBA_DEF_DEF_REL_\n"
      "\tBU_SG_REL_\n\tBU_EV_REL_\n\tBU_BO_REL_\n\tSG_MUL_VAL_\n\nBS_:\n\nBU_:";
  for (const auto& n : dbc.nodes) out += " " + names.Node(n);
  out += "\n";
  for (const auto& [name, values] : dbc.value_tables)
    out += fmt::format("VAL_TABLE_ {}{} ;\n", name, ValueDescriptions(values));
  out += "\n\n";
  WriteMessages(dbc, names, out);
  out += '\n';
  WriteComments(dbc, names, out);
  WriteDefinitions(dbc, names, out);
  WriteAttributes(dbc, names, out);
  WriteSignalTables(dbc, names, out);
  return out;
}

}  // namespace pumptherm::protocol
