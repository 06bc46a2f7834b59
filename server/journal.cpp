// SPDX-License-Identifier: MIT
#include "server/journal.h"

#include "trailmark/io/streams.h"

#include <fcntl.h>
#include <sqlite3.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <optional>
#include <stdexcept>
#include <tuple>

namespace trailmark::server {

namespace {

const char* kSalvageHint =
    "`trailmark journal export FILE --mission DIR --out OUT --salvage` writes what is readable";

struct Statement {
  Statement(sqlite3* db, const char* sql, const std::filesystem::path& file)
      : db(db), file(file) {
    if (sqlite3_prepare_v2(db, sql, -1, &stmt, nullptr) != SQLITE_OK) {
      throw std::runtime_error(file.string() + ": journal: " + sqlite3_errmsg(db));
    }
  }
  ~Statement() { sqlite3_finalize(stmt); }
  /// True for a row, false at the end; any other result is an error, never the end of data.
  bool Step() {
    const int rc = sqlite3_step(stmt);
    if (rc == SQLITE_ROW) return true;
    if (rc == SQLITE_DONE) return false;
    throw std::runtime_error(file.string() + ": journal: " + sqlite3_errmsg(db) +
                             " (the file is damaged; " + kSalvageHint + ")");
  }
  /// A column's text; a NULL (what a damaged row reads as) is an error.
  std::string Text(int column) const {
    const unsigned char* text = sqlite3_column_text(stmt, column);
    if (text == nullptr) {
      throw std::runtime_error(file.string() + ": journal: a row without its column " +
                               std::to_string(column) + " (the file is damaged; " +
                               kSalvageHint + ")");
    }
    return reinterpret_cast<const char*>(text);
  }
  sqlite3* db;
  const std::filesystem::path& file;
  sqlite3_stmt* stmt = nullptr;
};

/// What the high-water mark file says was acknowledged.
struct HighWaterMark {
  bool present = false;
  long long commits = 0, rows = 0;
};

constexpr const char* kHighWaterMarkFormat =
    "trailmark journal acknowledged: commits %020lld rows %020lld\n";

HighWaterMark ReadHighWaterMark(const std::filesystem::path& file) {
  HighWaterMark m;
  std::ifstream in(file);
  if (!in) return m;
  std::string line;
  std::getline(in, line);
  if (std::sscanf(line.c_str(), "trailmark journal acknowledged: commits %lld rows %lld", &m.commits,
                  &m.rows) != 2) {
    throw std::runtime_error(file.string() + ": not a journal high-water mark ('" + line + "')");
  }
  m.present = true;
  return m;
}

}  // namespace

struct Journal::Prepared {
  Prepared(sqlite3* db, const std::filesystem::path& file)
      : begin(db, "BEGIN IMMEDIATE", file),
        commit(db, "COMMIT", file),
        insert(db,
               "INSERT OR IGNORE INTO rows (stream, header, row, t, node) VALUES (?, ?, ?, ?, ?)",
               file),
        exists(db, "SELECT 1 FROM rows WHERE stream = ? AND row = ?", file),
        count(db, "UPDATE meta SET value = value + CASE key WHEN 'commits' THEN 1 ELSE ? END",
              file) {}
  /// Ready for the next use after an error part-way through a transaction.
  void ResetAll() {
    for (Statement* s : {&begin, &commit, &insert, &exists, &count}) sqlite3_reset(s->stmt);
    ClearBindings();
  }
  /// The rows' texts are bound without a copy: no statement keeps them past a transaction.
  void ClearBindings() {
    for (Statement* s : {&insert, &exists, &count}) sqlite3_clear_bindings(s->stmt);
  }
  Statement begin, commit, insert, exists, count;
};

Journal::Journal(const std::filesystem::path& file, Open mode)
    : mode_(mode), acked_file_(file.string() + ".acked"), file_(file) {
  const bool normal = mode == Open::kNormal;
  const HighWaterMark acked = ReadHighWaterMark(acked_file_);
  const std::string acked_text =
      acked.present ? std::to_string(acked.commits) + " commits (" + std::to_string(acked.rows) +
                          " rows) were acknowledged"
                    : "";
  std::error_code ec;
  const bool exists = std::filesystem::exists(file, ec);
  if (normal && exists && std::filesystem::file_size(file, ec) == 0) {
    throw std::runtime_error(
        file.string() + ": the journal is empty (0 bytes)" +
        (acked.present ? " but " + acked_text : std::string()) +
        ": refusing to take it for a new incident (remove it and " + acked_file_.string() +
        " to start one, or restore the journal)");
  }
  if (normal && !exists && acked.present && acked.commits > 0) {
    throw std::runtime_error(file.string() + ": the journal is missing but " + acked_text +
                             " (" + acked_file_.string() +
                             "): restore it, or remove the high-water mark to start a new "
                             "incident");
  }
  if (!normal && !exists) throw std::runtime_error(file.string() + ": no such journal");
  const int flags = normal ? SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE : SQLITE_OPEN_READONLY;
  if (sqlite3_open_v2(file.string().c_str(), &db_, flags, nullptr) != SQLITE_OK) {
    const std::string why = db_ ? sqlite3_errmsg(db_) : "out of memory";
    sqlite3_close(db_);
    db_ = nullptr;
    throw std::runtime_error(file.string() + ": cannot open the journal: " + why);
  }
  try {
    if (normal) {
      Exec("PRAGMA journal_mode=WAL");
      Exec("PRAGMA synchronous=FULL");  // a commit is on disk before it returns
    }
    {
      Statement check(db_, "PRAGMA quick_check", file_);
      const std::string verdict = check.Step() ? check.Text(0) : "no answer";
      if (verdict != "ok") {
        const std::string why = "the journal fails its integrity check (" + verdict + ")";
        if (normal) throw std::runtime_error(file_.string() + ": " + why + "; " + kSalvageHint);
        problems_.push_back(why);
      }
    }
    if (normal) {
      Exec(
          "CREATE TABLE IF NOT EXISTS rows (seq INTEGER PRIMARY KEY AUTOINCREMENT, stream TEXT "
          "NOT NULL, header TEXT NOT NULL, row TEXT NOT NULL, t REAL NOT NULL, node TEXT NOT "
          "NULL, UNIQUE(stream, row))");
      // Commits and rows counted in the transactions themselves (a journal of an older version
      // starts counting at its rows).
      Exec("CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value INTEGER NOT NULL)");
      Exec("INSERT OR IGNORE INTO meta VALUES ('commits', 0)");
      Exec("INSERT OR IGNORE INTO meta VALUES ('rows', (SELECT COUNT(*) FROM rows))");
    }
    try {
      std::tie(counted_commits_, counted_rows_) = Counted();
      if (acked.present && (counted_commits_ < acked.commits || counted_rows_ < acked.rows)) {
        const std::string why =
            "the journal holds " + std::to_string(counted_commits_) + " commits (" +
            std::to_string(counted_rows_) + " rows) but " + acked_text + " (" +
            acked_file_.string() +
            "): its write-ahead log was lost or damaged, or the file was rolled back";
        if (normal) throw std::runtime_error(file_.string() + ": " + why + "; " + kSalvageHint);
        problems_.push_back(why);
      }
      Statement last(db_, "SELECT stream, node, MAX(t) FROM rows GROUP BY stream, node", file_);
      while (last.Step()) {
        last_t_[{last.Text(0), last.Text(1)}] = sqlite3_column_double(last.stmt, 2);
      }
    } catch (const std::runtime_error& e) {
      if (normal) throw;
      problems_.push_back(e.what());  // salvage: export reads what it can
    }
    if (normal) {
      acked_fd_ = ::open(acked_file_.c_str(), O_WRONLY | O_CREAT, 0644);
      if (acked_fd_ < 0) {
        throw std::runtime_error(acked_file_.string() + ": cannot write the high-water mark: " +
                                 std::strerror(errno));
      }
      WriteHighWaterMark(counted_commits_, counted_rows_);
      prepared_ = std::make_unique<Prepared>(db_, file_);
    }
  } catch (...) {
    prepared_.reset();
    if (acked_fd_ >= 0) ::close(acked_fd_);
    sqlite3_close(db_);
    db_ = nullptr;
    throw;
  }
}

std::pair<long long, long long> Journal::Counted() const {
  long long commits = 0, rows = 0;
  bool have_meta = false;
  {
    Statement table(db_, "SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = 'meta'",
                    file_);
    have_meta = table.Step();
  }
  if (have_meta) {
    Statement meta(db_, "SELECT key, value FROM meta", file_);
    while (meta.Step()) {
      const std::string key = meta.Text(0);
      if (key == "commits") commits = sqlite3_column_int64(meta.stmt, 1);
      if (key == "rows") rows = sqlite3_column_int64(meta.stmt, 1);
    }
  }
  return {commits, rows};
}

void Journal::WriteHighWaterMark(long long commits, long long rows) {
  char text[128];
  const int n = std::snprintf(text, sizeof text, kHighWaterMarkFormat, commits, rows);
  if (::pwrite(acked_fd_, text, static_cast<std::size_t>(n), 0) != n || ::fdatasync(acked_fd_) != 0) {
    throw std::runtime_error(acked_file_.string() + ": cannot write the high-water mark: " +
                             std::strerror(errno));
  }
}

Journal::~Journal() {
  prepared_.reset();  // statements before the connection
  if (acked_fd_ >= 0) ::close(acked_fd_);
  sqlite3_close(db_);
}

void Journal::Exec(const char* sql) const {
  char* error = nullptr;
  if (sqlite3_exec(db_, sql, nullptr, nullptr, &error) != SQLITE_OK) {
    const std::string why = error ? error : "unknown error";
    sqlite3_free(error);
    throw std::runtime_error(file_.string() + ": journal: " + why);
  }
}

double Journal::LatestTime() const {
  double latest = -std::numeric_limits<double>::infinity();
  for (const auto& [key, t] : last_t_) latest = std::max(latest, t);
  return latest;
}

std::vector<Journal::AppendResult> Journal::AppendGroup(const std::vector<const Batch*>& batches) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (mode_ != Open::kNormal) throw std::runtime_error(file_.string() + ": opened to salvage only");
  std::vector<AppendResult> results(batches.size());
  // The times this transaction raises, with what they were (to restore on a rollback).
  std::vector<std::pair<std::map<std::pair<std::string, std::string>, double>::iterator,
                        std::optional<double>>>
      undo;
  Prepared& p = *prepared_;
  // The rows' texts outlive each step (bound without a copy; every statement is reset after
  // its step).
  auto bind = [](Statement& s, int column, const std::string& text) {
    sqlite3_bind_text(s.stmt, column, text.data(), static_cast<int>(text.size()), SQLITE_STATIC);
  };
  try {
    if (p.begin.Step()) throw std::runtime_error("unexpected row from BEGIN");
    sqlite3_reset(p.begin.stmt);
    for (std::size_t b = 0; b < batches.size(); ++b) {
      const Batch& batch = *batches[b];
      AppendResult& r = results[b];
      r.fresh.assign(batch.rows.size(), false);
      // Time order first, so that a refused batch journals nothing: a row older than its
      // node's last accepted one is a repeat (dropped) or out of order (the batch refused).
      std::vector<bool> repeat(batch.rows.size(), false);
      for (std::size_t i = 0; i < batch.rows.size() && r.error.empty(); ++i) {
        const auto it = last_t_.find(std::make_pair(batch.stream, batch.node[i]));
        // A stray time (issue 30): more than a day after the device's last row, or a new
        // device's first row more than a day from the incident's latest: refused, so it
        // neither moves the incident's clock nor locks the device out of its own time.
        const double reference =
            it != last_t_.end() ? it->second : LatestTime();
        const double jump = it != last_t_.end() ? batch.t[i] - reference
                                                : std::abs(batch.t[i] - reference);
        if (std::isfinite(reference) && jump > kMaxDeviceTimeGapS) {
          const std::size_t line = i < batch.lines.size() ? batch.lines[i] : i + 2;
          r.error = "request body:" + std::to_string(line) + ": t=" + std::to_string(batch.t[i]) +
                    " of '" + batch.node[i] + "' is more than a day from " +
                    (it != last_t_.end() ? "its last accepted row" : "the incident's latest row") +
                    " in " + batch.stream + " (t=" + std::to_string(reference) +
                    "): a stray time, not data";
          break;
        }
        if (it == last_t_.end() || batch.t[i] >= it->second) continue;
        bind(p.exists, 1, batch.stream);
        bind(p.exists, 2, batch.rows[i]);
        repeat[i] = p.exists.Step();
        sqlite3_reset(p.exists.stmt);
        if (!repeat[i]) {
          const std::size_t line = i < batch.lines.size() ? batch.lines[i] : i + 2;
          r.error = "request body:" + std::to_string(line) + ": t=" + std::to_string(batch.t[i]) +
                    " of '" + batch.node[i] + "' precedes its last accepted row in " +
                    batch.stream + " (t=" + std::to_string(it->second) +
                    "): a device's rows must arrive in time order";
        }
      }
      if (!r.error.empty()) continue;
      bind(p.insert, 1, batch.stream);
      bind(p.insert, 2, batch.header);
      for (std::size_t i = 0; i < batch.rows.size(); ++i) {
        if (repeat[i]) {
          ++r.duplicates;
          continue;
        }
        bind(p.insert, 3, batch.rows[i]);
        sqlite3_bind_double(p.insert.stmt, 4, batch.t[i]);
        bind(p.insert, 5, batch.node[i]);
        if (sqlite3_step(p.insert.stmt) != SQLITE_DONE) {
          const std::string why = sqlite3_errmsg(db_);  // before the reset
          sqlite3_reset(p.insert.stmt);
          throw std::runtime_error(why);
        }
        sqlite3_reset(p.insert.stmt);
        if (sqlite3_changes(db_) == 1) {
          ++r.accepted;
          r.fresh[i] = true;
          const auto [it, first] = last_t_.emplace(std::make_pair(batch.stream, batch.node[i]),
                                                   batch.t[i]);
          if (first) {
            undo.emplace_back(it, std::nullopt);
          } else if (batch.t[i] > it->second) {
            undo.emplace_back(it, it->second);
            it->second = batch.t[i];
          }
        } else {
          ++r.duplicates;
        }
      }
    }
    long long accepted = 0;
    for (const auto& r : results) accepted += static_cast<long long>(r.accepted);
    sqlite3_bind_int64(p.count.stmt, 1, accepted);
    const bool row = p.count.Step();
    sqlite3_reset(p.count.stmt);
    if (row) throw std::runtime_error("unexpected row from UPDATE");
    p.ClearBindings();
    if (p.commit.Step()) throw std::runtime_error("unexpected row from COMMIT");
    sqlite3_reset(p.commit.stmt);
    ++commits_;
    counted_commits_ += 1;
    counted_rows_ += accepted;
  } catch (const std::exception& e) {
    p.ResetAll();
    sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
    // Newest first: an entry added here is erased, a raised time goes back.
    for (auto u = undo.rbegin(); u != undo.rend(); ++u) {
      if (u->second) {
        u->first->second = *u->second;
      } else {
        last_t_.erase(u->first);
      }
    }
    throw std::runtime_error(file_.string() + ": journal: " + e.what());
  }
  // Committed; acknowledged only once the high-water mark says so (else the caller answers
  // that nothing was acknowledged, and a redelivery is a duplicate).
  WriteHighWaterMark(counted_commits_, counted_rows_);
  return results;
}

void Journal::ForEach(const std::function<void(const std::string&, const std::string&,
                                               const std::string&)>& visit) const {
  std::lock_guard<std::mutex> lock(mutex_);
  Statement select(db_, "SELECT stream, header, row FROM rows ORDER BY seq", file_);
  while (select.Step()) visit(select.Text(0), select.Text(1), select.Text(2));
}

std::size_t Journal::size() const {
  std::lock_guard<std::mutex> lock(mutex_);
  Statement count(db_, "SELECT COUNT(*) FROM rows", file_);
  if (!count.Step()) throw std::runtime_error(file_.string() + ": journal: no row count");
  return static_cast<std::size_t>(sqlite3_column_int64(count.stmt, 0));
}

std::size_t Journal::Export(const std::filesystem::path& dir,
                            const std::filesystem::path& mission_json) {
  std::lock_guard<std::mutex> lock(mutex_);
  // Every readable row by seq (a damaged page stops a query: salvage resumes after it), then
  // each stream in time order, arrival order among equal times.
  struct Row {
    double t;
    long long seq;
    std::string row;
  };
  std::map<std::string, std::pair<std::string, std::vector<Row>>> streams;  // header, rows
  long long next = 0, skip = 1;
  for (int attempt = 0; attempt < 64; ++attempt) {
    Statement select(db_,
                     "SELECT seq, stream, header, row, t FROM rows WHERE seq >= ? ORDER BY seq",
                     file_);
    sqlite3_bind_int64(select.stmt, 1, next);
    try {
      while (select.Step()) {
        const long long seq = sqlite3_column_int64(select.stmt, 0);
        auto& [header, rows] = streams[select.Text(1)];
        if (header.empty()) header = select.Text(2);
        rows.push_back({sqlite3_column_double(select.stmt, 4), seq, select.Text(3)});
        next = seq + 1;
        skip = 1;
      }
      break;
    } catch (const std::runtime_error& e) {
      if (mode_ != Open::kSalvage) throw;
      problems_.push_back(std::string("unreadable rows from seq ") + std::to_string(next) +
                          " on (" + e.what() + ")");
      next += skip;  // past the damaged rows, further each time
      skip *= 2;
    }
  }
  std::filesystem::create_directories(dir);
  std::filesystem::copy_file(mission_json, dir / "mission.json",
                             std::filesystem::copy_options::overwrite_existing);
  std::size_t written = 0;
  for (auto& [stream, content] : streams) {
    auto& rows = content.second;
    std::stable_sort(rows.begin(), rows.end(), [](const Row& a, const Row& b) {
      return a.t != b.t ? a.t < b.t : a.seq < b.seq;
    });
    std::ofstream out(dir / stream);
    out << content.first << "\n";
    for (const Row& r : rows) out << r.row << "\n";
    out.close();
    if (!out) throw std::runtime_error((dir / stream).string() + ": cannot write the export");
    written += rows.size();
  }
  return written;
}

}  // namespace trailmark::server
