#include "tools/common/csv.hpp"

#include <fmt/format.h>

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iostream>
#include <iterator>
#include <sstream>
#include <system_error>

namespace pumptherm::tools {
namespace {

std::string_view Trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r'))
    s.remove_suffix(1);
  return s;
}

std::vector<std::string> SplitCells(std::string_view line) {
  std::vector<std::string> cells;
  std::size_t start = 0;
  for (;;) {
    const std::size_t comma = line.find(',', start);
    cells.emplace_back(Trim(line.substr(
        start, comma == std::string_view::npos ? std::string_view::npos : comma - start)));
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  return cells;
}

/// Column names renamed to one name per quantity (docs/daemon.md, "Names"): old -> current.
/// Files written before keep working. `winding_sd_K` of old `identify` output is not among them:
/// it is also the standard deviation of a model node named "winding".
struct RenamedColumn {
  std::string_view old_name, name;
};
constexpr RenamedColumn kRenamedColumns[] = {
    {"winding_res_C", "winding_resistance_degC"},  // pumptherm plant's truth
    {"winding_degC", "winding_resistance_degC"},   // pumptherm identify
    {"frame_measured_C", "frame_sensor_degC"},     // pumpthermd --csv-dir
};

}  // namespace

void CsvTable::RenameDeprecatedColumns(std::size_t header_line) {
  for (const RenamedColumn& r : kRenamedColumns) {
    const auto old_index = Index(r.old_name);
    if (!old_index || Index(r.name)) continue;
    columns_[*old_index] = std::string(r.name);
    deprecations_.push_back(fmt::format("{}:{}: column '{}' is deprecated: read as '{}'", source_,
                                        header_line, r.old_name, r.name));
    fmt::print(stderr, "warning: {}\n", deprecations_.back());
  }
}

CsvTable CsvTable::Parse(std::string_view text, std::string source) {
  CsvTable t;
  t.source_ = std::move(source);
  std::size_t line_no = 0;
  std::size_t pos = 0;
  // A UTF-8 byte order mark before the header is tolerated.
  if (text.substr(0, 3) == "\xEF\xBB\xBF") pos = 3;
  bool have_header = false;
  while (pos < text.size()) {
    std::size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    const std::string_view line = Trim(text.substr(pos, end - pos));
    pos = end + 1;
    ++line_no;
    if (line.empty()) continue;
    if (!have_header) {
      t.columns_ = SplitCells(line);
      for (std::size_t i = 0; i < t.columns_.size(); ++i) {
        if (t.columns_[i].empty()) {
          throw CsvError(
              fmt::format("{}:{}: column {} of the header has no name", t.source_, line_no, i + 1));
        }
        for (std::size_t j = 0; j < i; ++j) {
          if (t.columns_[j] == t.columns_[i]) {
            throw CsvError(fmt::format("{}:{}: column '{}' appears twice in the header", t.source_,
                                       line_no, t.columns_[i]));
          }
        }
      }
      t.RenameDeprecatedColumns(line_no);
      have_header = true;
      continue;
    }
    auto cells = SplitCells(line);
    if (cells.size() != t.columns_.size()) {
      throw CsvError(fmt::format("{}: row {}: {} cells, but the header has {} columns", t.source_,
                                 line_no, cells.size(), t.columns_.size()));
    }
    t.rows_.push_back(std::move(cells));
    t.lines_.push_back(line_no);
  }
  if (!have_header) throw CsvError(fmt::format("{}: empty file: expected a header row", t.source_));
  return t;
}

CsvTable CsvTable::Read(const std::string& path) {
  std::string text;
  if (path == "-") {
    text.assign(std::istreambuf_iterator<char>(std::cin), std::istreambuf_iterator<char>());
    return Parse(text, "<stdin>");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) throw CsvError(fmt::format("{}: cannot open: {}", path, std::strerror(errno)));
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) throw CsvError(fmt::format("{}: read error: {}", path, std::strerror(errno)));
  return Parse(ss.str(), path);
}

std::optional<std::size_t> CsvTable::Index(std::string_view column) const {
  for (std::size_t i = 0; i < columns_.size(); ++i) {
    if (columns_[i] == column) return i;
  }
  // The other spelling of a temperature's unit: `_C` and `_degC` name the same quantity.
  std::string other;
  if (column.ends_with("_degC")) {
    other = std::string(column.substr(0, column.size() - 5)) + "_C";
  } else if (column.ends_with("_C")) {
    other = std::string(column.substr(0, column.size() - 2)) + "_degC";
  } else {
    return std::nullopt;
  }
  for (std::size_t i = 0; i < columns_.size(); ++i) {
    if (columns_[i] == other) return i;
  }
  return std::nullopt;
}

std::vector<std::string> CsvTable::Text(std::string_view column) const {
  const auto index = Index(column);
  if (!index) {
    throw CsvError(fmt::format("{}: missing column '{}' (the header has: {})", source_, column,
                               fmt::join(columns_, ", ")));
  }
  std::vector<std::string> out;
  out.reserve(rows_.size());
  for (const auto& row : rows_) out.push_back(row[*index]);
  return out;
}

std::vector<double> CsvTable::Codes(std::string_view column,
                                    std::span<const std::string_view> words) const {
  const std::vector<std::string> cells = Text(column);
  std::vector<double> out;
  out.reserve(cells.size());
  for (std::size_t r = 0; r < cells.size(); ++r) {
    const std::string& cell = cells[r];
    if (cell.empty() || cell == "nan" || cell == "NaN" || cell == "NAN") {
      out.push_back(std::nan(""));
      continue;
    }
    bool found = false;
    for (std::size_t k = 0; k < words.size() && !found; ++k) {
      if (cell == words[k]) {
        out.push_back(static_cast<double>(k));
        found = true;
      }
    }
    if (found) continue;
    double v = 0.0;
    const auto [ptr, ec] = std::from_chars(cell.data(), cell.data() + cell.size(), v);
    if (ec != std::errc() || ptr != cell.data() + cell.size() || !std::isfinite(v)) {
      throw CsvError(fmt::format("{}: row {}, column '{}': '{}' is neither a number nor one of {}",
                                 source_, lines_[r], column, cell, fmt::join(words, ", ")));
    }
    out.push_back(v);
  }
  return out;
}

std::vector<double> CsvTable::Numbers(std::string_view column, bool allow_nan) const {
  const auto index = Index(column);
  if (!index) {
    throw CsvError(fmt::format("{}: missing column '{}' (the header has: {})", source_, column,
                               fmt::join(columns_, ", ")));
  }
  std::vector<double> out;
  out.reserve(rows_.size());
  for (std::size_t r = 0; r < rows_.size(); ++r) {
    const std::string& cell = rows_[r][*index];
    if (allow_nan && (cell.empty() || cell == "nan" || cell == "NaN" || cell == "NAN")) {
      out.push_back(std::nan(""));
      continue;
    }
    if (cell.empty()) {
      throw CsvError(
          fmt::format("{}: row {}, column '{}': empty cell", source_, lines_[r], column));
    }
    double v = 0.0;
    const char* first = cell.data();
    if (*first == '+') ++first;
    const auto [ptr, ec] = std::from_chars(first, cell.data() + cell.size(), v);
    if (ec != std::errc() || ptr != cell.data() + cell.size()) {
      throw CsvError(fmt::format("{}: row {}, column '{}': '{}' is not a number", source_,
                                 lines_[r], column, cell));
    }
    if (!std::isfinite(v)) {
      throw CsvError(fmt::format("{}: row {}, column '{}': '{}' is not a finite number", source_,
                                 lines_[r], column, cell));
    }
    out.push_back(v);
  }
  return out;
}

std::vector<double> CsvTable::Column(std::string_view column) const {
  return Numbers(column, false);
}

std::vector<double> CsvTable::ColumnAllowingNaN(std::string_view column) const {
  return Numbers(column, true);
}

std::vector<double> CsvTable::Time(std::string_view column) const {
  auto t = Column(column);
  for (std::size_t r = 1; r < t.size(); ++r) {
    if (!(t[r] > t[r - 1])) {
      throw CsvError(fmt::format("{}: row {}, column '{}': time {} does not advance past {}",
                                 source_, lines_[r], column, t[r], t[r - 1]));
    }
  }
  return t;
}

CsvWriter::CsvWriter(const std::string& path, std::vector<std::string> columns)
    : path_(path), columns_(columns.size()) {
  if (path == "-") {
    file_ = stdout;
  } else {
    file_ = std::fopen(path.c_str(), "w");
    if (file_ == nullptr) {
      throw std::system_error(errno, std::generic_category(), "cannot create " + path);
    }
    owned_ = true;
  }
  const std::string header = fmt::format("{}\n", fmt::join(columns, ","));
  std::fputs(header.c_str(), file_);
}

CsvWriter::~CsvWriter() {
  if (owned_ && file_ != nullptr) std::fclose(file_);
}

void CsvWriter::Row(const std::vector<double>& values) { Row(values, {}); }

void CsvWriter::Row(const std::vector<double>& values, const std::vector<std::string>& text) {
  if (values.size() + text.size() != columns_) {
    throw std::logic_error(
        fmt::format("CsvWriter {}: row of {} values and {} text cells for {} columns", path_,
                    values.size(), text.size(), columns_));
  }
  line_.clear();
  for (std::size_t i = 0; i < values.size(); ++i) {
    if (i) line_ += ',';
    if (std::isnan(values[i])) {
      line_ += "nan";
    } else {
      fmt::format_to(std::back_inserter(line_), "{}", values[i]);
    }
  }
  for (std::size_t i = 0; i < text.size(); ++i) {
    if (i || !values.empty()) line_ += ',';
    if (text[i].find_first_of(",\"\n\r") != std::string::npos) {
      throw std::logic_error(
          fmt::format("CsvWriter {}: text cell '{}' needs quoting", path_, text[i]));
    }
    line_ += text[i];
  }
  line_ += '\n';
  std::fwrite(line_.data(), 1, line_.size(), file_);
}

void CsvWriter::Close() {
  if (file_ == nullptr) return;
  const bool bad = std::fflush(file_) != 0 || std::ferror(file_);
  const int err = errno;
  if (owned_) std::fclose(file_);
  file_ = nullptr;
  if (bad) throw std::system_error(err, std::generic_category(), "cannot write " + path_);
}

}  // namespace pumptherm::tools
