#include "server/journal.h"

#include <sqlite3.h>

#include <algorithm>
#include <fstream>
#include <map>
#include <stdexcept>

namespace trailmark::server {

namespace {

struct Statement {
  Statement(sqlite3* db, const char* sql, const std::filesystem::path& file) {
    if (sqlite3_prepare_v2(db, sql, -1, &stmt, nullptr) != SQLITE_OK) {
      throw std::runtime_error(file.string() + ": journal: " + sqlite3_errmsg(db));
    }
  }
  ~Statement() { sqlite3_finalize(stmt); }
  sqlite3_stmt* stmt = nullptr;
};

}  // namespace

Journal::Journal(const std::filesystem::path& file) : file_(file) {
  if (sqlite3_open(file.string().c_str(), &db_) != SQLITE_OK) {
    const std::string why = db_ ? sqlite3_errmsg(db_) : "out of memory";
    sqlite3_close(db_);
    db_ = nullptr;
    throw std::runtime_error(file.string() + ": cannot open the journal: " + why);
  }
  Exec("PRAGMA journal_mode=WAL");
  Exec("PRAGMA synchronous=FULL");  // a commit is on disk before it returns
  Exec(
      "CREATE TABLE IF NOT EXISTS rows (seq INTEGER PRIMARY KEY AUTOINCREMENT, stream TEXT NOT "
      "NULL, header TEXT NOT NULL, row TEXT NOT NULL, t REAL NOT NULL, node TEXT NOT NULL, "
      "UNIQUE(stream, row))");
  Statement last(db_, "SELECT stream, node, MAX(t) FROM rows GROUP BY stream, node", file_);
  while (sqlite3_step(last.stmt) == SQLITE_ROW) {
    last_t_[{reinterpret_cast<const char*>(sqlite3_column_text(last.stmt, 0)),
             reinterpret_cast<const char*>(sqlite3_column_text(last.stmt, 1))}] =
        sqlite3_column_double(last.stmt, 2);
  }
}

Journal::~Journal() { sqlite3_close(db_); }

void Journal::Exec(const char* sql) const {
  char* error = nullptr;
  if (sqlite3_exec(db_, sql, nullptr, nullptr, &error) != SQLITE_OK) {
    const std::string why = error ? error : "unknown error";
    sqlite3_free(error);
    throw std::runtime_error(file_.string() + ": journal: " + why);
  }
}

std::vector<Journal::AppendResult> Journal::AppendGroup(const std::vector<const Batch*>& batches) {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<AppendResult> results(batches.size());
  const auto last_before = last_t_;
  Exec("BEGIN IMMEDIATE");
  try {
    Statement insert(db_,
                     "INSERT OR IGNORE INTO rows (stream, header, row, t, node) VALUES (?, ?, ?, ?, ?)",
                     file_);
    Statement exists(db_, "SELECT 1 FROM rows WHERE stream = ? AND row = ?", file_);
    for (std::size_t b = 0; b < batches.size(); ++b) {
      const Batch& batch = *batches[b];
      AppendResult& r = results[b];
      r.fresh.assign(batch.rows.size(), false);
      // Time order first, so that a refused batch journals nothing: a row older than its
      // node's last accepted one is a repeat (dropped) or out of order (the batch refused).
      std::vector<bool> repeat(batch.rows.size(), false);
      for (std::size_t i = 0; i < batch.rows.size() && r.error.empty(); ++i) {
        const auto key = std::make_pair(batch.stream, batch.node[i]);
        const auto it = last_t_.find(key);
        if (it == last_t_.end() || batch.t[i] >= it->second) continue;
        sqlite3_bind_text(exists.stmt, 1, batch.stream.c_str(), -1, SQLITE_TRANSIENT);
        sqlite3_bind_text(exists.stmt, 2, batch.rows[i].c_str(), -1, SQLITE_TRANSIENT);
        repeat[i] = sqlite3_step(exists.stmt) == SQLITE_ROW;
        sqlite3_reset(exists.stmt);
        if (!repeat[i]) {
          const std::size_t line = i < batch.lines.size() ? batch.lines[i] : i + 2;
          r.error = "request body:" + std::to_string(line) + ": t=" + std::to_string(batch.t[i]) +
                    " of '" + batch.node[i] + "' precedes its last accepted row in " +
                    batch.stream + " (t=" + std::to_string(it->second) +
                    "): a device's rows must arrive in time order";
        }
      }
      if (!r.error.empty()) continue;
      for (std::size_t i = 0; i < batch.rows.size(); ++i) {
        if (repeat[i]) {
          ++r.duplicates;
          continue;
        }
        sqlite3_bind_text(insert.stmt, 1, batch.stream.c_str(), -1, SQLITE_TRANSIENT);
        sqlite3_bind_text(insert.stmt, 2, batch.header.c_str(), -1, SQLITE_TRANSIENT);
        sqlite3_bind_text(insert.stmt, 3, batch.rows[i].c_str(), -1, SQLITE_TRANSIENT);
        sqlite3_bind_double(insert.stmt, 4, batch.t[i]);
        sqlite3_bind_text(insert.stmt, 5, batch.node[i].c_str(), -1, SQLITE_TRANSIENT);
        if (sqlite3_step(insert.stmt) != SQLITE_DONE) throw std::runtime_error(sqlite3_errmsg(db_));
        sqlite3_reset(insert.stmt);
        if (sqlite3_changes(db_) == 1) {
          ++r.accepted;
          r.fresh[i] = true;
          const auto [it, first] = last_t_.emplace(std::make_pair(batch.stream, batch.node[i]),
                                                   batch.t[i]);
          if (!first) it->second = std::max(it->second, batch.t[i]);
        } else {
          ++r.duplicates;
        }
      }
    }
    Exec("COMMIT");
    ++commits_;
  } catch (const std::exception& e) {
    sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
    last_t_ = last_before;
    throw std::runtime_error(file_.string() + ": journal: " + e.what());
  }
  return results;
}

void Journal::ForEach(const std::function<void(const std::string&, const std::string&,
                                               const std::string&)>& visit) const {
  std::lock_guard<std::mutex> lock(mutex_);
  Statement select(db_, "SELECT stream, header, row FROM rows ORDER BY seq", file_);
  while (sqlite3_step(select.stmt) == SQLITE_ROW) {
    visit(reinterpret_cast<const char*>(sqlite3_column_text(select.stmt, 0)),
          reinterpret_cast<const char*>(sqlite3_column_text(select.stmt, 1)),
          reinterpret_cast<const char*>(sqlite3_column_text(select.stmt, 2)));
  }
}

std::size_t Journal::size() const {
  std::lock_guard<std::mutex> lock(mutex_);
  Statement count(db_, "SELECT COUNT(*) FROM rows", file_);
  return sqlite3_step(count.stmt) == SQLITE_ROW
             ? static_cast<std::size_t>(sqlite3_column_int64(count.stmt, 0))
             : 0;
}

void Journal::Export(const std::filesystem::path& dir,
                     const std::filesystem::path& mission_json) const {
  std::filesystem::create_directories(dir);
  std::filesystem::copy_file(mission_json, dir / "mission.json",
                             std::filesystem::copy_options::overwrite_existing);
  std::lock_guard<std::mutex> lock(mutex_);
  std::map<std::string, std::ofstream> files;
  Statement select(db_, "SELECT stream, header, row FROM rows ORDER BY stream, t, seq", file_);
  while (sqlite3_step(select.stmt) == SQLITE_ROW) {
    const std::string stream = reinterpret_cast<const char*>(sqlite3_column_text(select.stmt, 0));
    auto it = files.find(stream);
    if (it == files.end()) {
      it = files.emplace(stream, std::ofstream(dir / stream)).first;
      it->second << reinterpret_cast<const char*>(sqlite3_column_text(select.stmt, 1)) << "\n";
    }
    it->second << reinterpret_cast<const char*>(sqlite3_column_text(select.stmt, 2)) << "\n";
  }
  for (auto& [name, f] : files) {
    f.close();
    if (!f) throw std::runtime_error((dir / name).string() + ": cannot write the export");
  }
}

}  // namespace trailmark::server
