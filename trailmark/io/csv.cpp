// SPDX-License-Identifier: MIT
#include "trailmark/io/csv.h"

#include <fmt/format.h>

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <stdexcept>

#include "trailmark/core/error.h"
#include "trailmark/core/types.h"

namespace trailmark {
namespace {

std::string_view Trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  return s;
}

std::string Printable(std::string_view s) {
  std::string out;
  for (char c : s.substr(0, 40)) {
    out += (static_cast<unsigned char>(c) < 0x20) ? '?' : c;
  }
  if (s.size() > 40) out += "...";
  return out;
}

}  // namespace

std::optional<double> ParseFiniteDouble(std::string_view text) {
  text = Trim(text);
  if (!text.empty() && text.front() == '+') text.remove_prefix(1);
  if (text.empty()) return std::nullopt;
  double value = 0.0;
  const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (ec != std::errc() || ptr != text.data() + text.size() || !std::isfinite(value)) {
    return std::nullopt;
  }
  return value;
}

CsvReader::CsvReader(std::string path, Options options)
    : path_(std::move(path)), options_(options) {
  std::error_code ec;
  if (!std::filesystem::exists(path_, ec)) throw InputError(path_, 0, "file does not exist");
  if (std::filesystem::is_directory(path_, ec)) throw InputError(path_, 0, "is a directory");
  file_ = std::fopen(path_.c_str(), "rb");
  if (file_ == nullptr) {
    throw InputError(path_, 0, fmt::format("cannot open: {}", std::strerror(errno)));
  }
  file_size_ = static_cast<std::size_t>(std::filesystem::file_size(path_, ec));
  ReadHeaderOrClose();
}

CsvReader::CsvReader(std::string name, std::string_view content, Options options)
    : path_(std::move(name)), options_(options) {
  if (content.empty()) {
    throw InputError(path_, 0, "empty file: expected a header line naming the columns");
  }
  // fmemopen reads the caller's buffer in place (read-only mode never writes to it).
  file_ = fmemopen(const_cast<char*>(content.data()), content.size(), "r");
  if (file_ == nullptr) {
    throw InputError(path_, 0, fmt::format("cannot read: {}", std::strerror(errno)));
  }
  file_size_ = content.size();
  ReadHeaderOrClose();
}

void CsvReader::ReadHeaderOrClose() {
  try {
    ReadHeader();
  } catch (...) {
    std::fclose(file_);  // the destructor does not run when a constructor throws
    file_ = nullptr;
    throw;
  }
}

void CsvReader::ReadHeader() {
  buffer_.resize(std::max(options_.chunk_bytes, options_.max_line_bytes) * 2);

  std::string_view line;
  while (true) {
    if (!ReadLine(&line)) {
      throw InputError(path_, line_number_ == 0 ? 0 : line_number_,
                       "empty file: expected a header line naming the columns");
    }
    if (line_number_ == 1 && line.size() >= 3 && line.substr(0, 3) == "\xEF\xBB\xBF") {
      line.remove_prefix(3);  // UTF-8 byte order mark
    }
    const std::string_view t = Trim(line);
    if (t.empty() || t.front() == '#') continue;
    break;
  }
  SplitFields(line);
  for (std::size_t i = 0; i < fields_.size(); ++i) {
    const std::string name(Trim(fields_[i]));
    if (name.empty() && !options_.allow_unnamed_columns) {
      Fail(fmt::format("header: column {} has an empty name", i + 1));
    }
    // A name twice is an error only when that column is read (Column): extra columns, which
    // readers ignore, may repeat a name.
    header_.push_back(name);
  }
}

CsvReader::~CsvReader() {
  if (file_ != nullptr) std::fclose(file_);
}

int CsvReader::Column(std::string_view name) const {
  int found = -1;
  for (std::size_t i = 0; i < header_.size(); ++i) {
    if (header_[i] != name) continue;
    if (found >= 0) {
      throw InputError(path_, 1, fmt::format("header: column '{}' appears twice", name));
    }
    found = static_cast<int>(i);
  }
  return found;
}

int CsvReader::RequireColumn(std::string_view name) const {
  const int col = Column(name);
  if (col < 0) {
    std::string have;
    for (const auto& h : header_) have += (have.empty() ? "" : ",") + h;
    throw InputError(path_, 1, fmt::format("missing column '{}' (header has: {})", name, have));
  }
  return col;
}

bool CsvReader::ReadLine(std::string_view* line) {
  while (true) {
    const char* start = buffer_.data() + begin_;
    const void* nl = std::memchr(start, '\n', end_ - begin_);
    if (nl != nullptr) {
      const std::size_t len = static_cast<const char*>(nl) - start;
      if (len > options_.max_line_bytes) {
        ++line_number_;
        Fail(fmt::format("line longer than {} bytes: not a CSV text file?",
                         options_.max_line_bytes));
      }
      *line = std::string_view(start, len);
      begin_ += len + 1;
      bytes_consumed_ += len + 1;
      ++line_number_;
      if (!line->empty() && line->back() == '\r') line->remove_suffix(1);
      if (std::memchr(line->data(), '\0', line->size()) != nullptr) {
        Fail("contains a NUL byte: binary data, not a CSV text file");
      }
      return true;
    }
    if (end_ - begin_ > options_.max_line_bytes) {
      ++line_number_;
      Fail(fmt::format("line longer than {} bytes: not a CSV text file?",
                       options_.max_line_bytes));
    }
    if (eof_) {
      if (end_ == begin_) return false;
      // Last line without a terminating newline.
      *line = std::string_view(buffer_.data() + begin_, end_ - begin_);
      bytes_consumed_ += end_ - begin_;
      begin_ = end_;
      ++line_number_;
      last_line_unterminated_ = true;
      if (!line->empty() && line->back() == '\r') line->remove_suffix(1);
      if (std::memchr(line->data(), '\0', line->size()) != nullptr) {
        Fail("contains a NUL byte: binary data, not a CSV text file");
      }
      return true;
    }
    // Compact and refill.
    if (begin_ > 0) {
      std::memmove(buffer_.data(), buffer_.data() + begin_, end_ - begin_);
      end_ -= begin_;
      begin_ = 0;
    }
    const std::size_t want = buffer_.size() - end_;
    const std::size_t got = std::fread(buffer_.data() + end_, 1, want, file_);
    if (got < want) {
      if (std::ferror(file_)) Fail(fmt::format("read error: {}", std::strerror(errno)));
      eof_ = true;
    }
    end_ += got;
  }
}

void CsvReader::SplitFields(std::string_view line) {
  fields_.clear();
  std::size_t i = 0;
  while (true) {
    if (i < line.size() && line[i] == '"') {
      // Quoted field: runs to the closing quote; "" inside stays as is (only extra,
      // ignored columns can need quotes: ids and numbers never do).
      std::size_t j = i + 1;
      while (true) {
        if (j >= line.size()) Fail("unterminated quoted field");
        if (line[j] == '"') {
          if (j + 1 < line.size() && line[j + 1] == '"') {
            j += 2;
            continue;
          }
          break;
        }
        ++j;
      }
      fields_.push_back(line.substr(i + 1, j - i - 1));
      i = j + 1;
      if (i < line.size() && line[i] != ',') Fail("text after a closing quote");
    } else {
      const std::size_t comma = line.find(',', i);
      const std::size_t end = comma == std::string_view::npos ? line.size() : comma;
      fields_.push_back(line.substr(i, end - i));
      i = end;
    }
    if (i >= line.size()) break;
    ++i;  // skip the comma
    if (i == line.size()) {
      fields_.push_back(std::string_view());
      break;
    }
  }
}

bool CsvReader::Next() {
  std::string_view line;
  while (ReadLine(&line)) {
    const std::string_view t = Trim(line);
    if (t.empty() || t.front() == '#') continue;
    SplitFields(line);
    if (fields_.size() != header_.size()) {
      if (last_line_unterminated_ && fields_.size() < header_.size()) {
        Fail(fmt::format("truncated last line: {} of {} fields and no final newline",
                         fields_.size(), header_.size()));
      }
      Fail(fmt::format("expected {} fields as in the header, found {}", header_.size(),
                       fields_.size()));
    }
    return true;
  }
  return false;
}

std::string CsvReader::ColumnName(int col) const {
  return col >= 0 && static_cast<std::size_t>(col) < header_.size() ? header_[col] : "?";
}

double CsvReader::Double(int col) const {
  const std::string_view cell = Trim(Field(col));
  if (cell.empty()) Fail(fmt::format("column '{}': empty cell where a number is required",
                                     ColumnName(col)));
  if (auto v = ParseFiniteDouble(cell)) return *v;
  Fail(fmt::format("column '{}': '{}' is not a finite number", ColumnName(col), Printable(cell)));
}

std::optional<double> CsvReader::OptionalDouble(int col) const {
  if (col < 0) return std::nullopt;
  const std::string_view cell = Trim(Field(col));
  if (cell.empty()) return std::nullopt;
  return Double(col);
}

std::string_view CsvReader::NodeId(int col) const {
  const std::string_view cell = Trim(Field(col));
  if (!IsValidNodeId(cell)) {
    Fail(fmt::format("column '{}': '{}' is not a node id (non-empty, [A-Za-z0-9_.-])",
                     ColumnName(col), Printable(cell)));
  }
  return cell;
}

void CsvReader::Fail(const std::string& problem) const {
  throw InputError(path_, line_number_, problem);
}

CsvWriter::CsvWriter(std::string path, const std::vector<std::string>& header)
    : path_(std::move(path)), columns_(header.size()) {
  file_ = std::fopen(path_.c_str(), "wb");
  if (file_ == nullptr) {
    throw std::runtime_error(fmt::format("{}: cannot write: {}", path_, std::strerror(errno)));
  }
  std::setvbuf(file_, nullptr, _IOFBF, 1 << 20);
  for (const auto& h : header) Add(std::string_view(h));
  EndRow();
  rows_ = 0;
}

CsvWriter::CsvWriter(std::string name, const std::vector<std::string>& header,
                     std::vector<std::string>* lines)
    : path_(std::move(name)), lines_(lines), columns_(header.size()) {
  for (const auto& h : header) Add(std::string_view(h));
  EndRow();
  rows_ = 0;
}

CsvWriter::~CsvWriter() {
  if (file_ != nullptr) std::fclose(file_);
}

void CsvWriter::Separator() {
  if (cells_in_row_++ > 0) row_ += ',';
}

CsvWriter& CsvWriter::Add(double value) {
  if (!std::isfinite(value)) {
    throw std::logic_error(fmt::format("{}: row {}: refusing to write a non-finite number", path_,
                                       rows_ + 1));
  }
  Separator();
  // The shortest text that reads back to the same double (std::to_chars), in fixed notation
  // from 1e-5 to 1e16 (times, positions and sigmas read as written: 100000, 0.0001) and in
  // scientific beyond.
  char text[400];  // (fixed notation of 1e16 needs 17 digits, of 1e-5 a few more: far below)
  const double magnitude = std::abs(value);
  const bool fixed = magnitude == 0 || (magnitude >= 1e-5 && magnitude < 1e16);
  const auto [end, error] =
      fixed ? std::to_chars(text, text + sizeof text, value, std::chars_format::fixed)
            : std::to_chars(text, text + sizeof text, value);
  (void)error;  // (the buffer holds any double in either notation)
  row_.append(text, end);
  return *this;
}

CsvWriter& CsvWriter::Add(std::optional<double> value) {
  if (value) return Add(*value);
  Separator();
  return *this;
}

CsvWriter& CsvWriter::Add(std::string_view text) {
  Separator();
  row_ += text;
  return *this;
}

void CsvWriter::EndRow() {
  if (cells_in_row_ != columns_) {
    throw std::logic_error(fmt::format("{}: row {} has {} cells for {} columns", path_, rows_ + 1,
                                       cells_in_row_, columns_));
  }
  if (lines_ != nullptr) {
    lines_->push_back(row_);
  } else {
    row_ += '\n';
    std::fwrite(row_.data(), 1, row_.size(), file_);
  }
  row_.clear();
  cells_in_row_ = 0;
  ++rows_;
}

void CsvWriter::Close() {
  if (file_ == nullptr) return;
  const bool failed = std::fflush(file_) != 0 || std::ferror(file_) != 0;
  std::fclose(file_);
  file_ = nullptr;
  if (failed) throw std::runtime_error(fmt::format("{}: write failed (disk full?)", path_));
}

}  // namespace trailmark
