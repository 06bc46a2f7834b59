#include "server/journal.h"

#include <sqlite3.h>

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
      "NULL, "
      "header TEXT NOT NULL, row TEXT NOT NULL, UNIQUE(stream, row))");
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

Journal::AppendResult Journal::Append(const std::string& stream, const std::string& header,
                                      const std::vector<std::string>& rows) {
  AppendResult r;
  Exec("BEGIN IMMEDIATE");
  try {
    Statement insert(db_, "INSERT OR IGNORE INTO rows (stream, header, row) VALUES (?, ?, ?)",
                     file_);
    for (const auto& row : rows) {
      sqlite3_bind_text(insert.stmt, 1, stream.c_str(), -1, SQLITE_TRANSIENT);
      sqlite3_bind_text(insert.stmt, 2, header.c_str(), -1, SQLITE_TRANSIENT);
      sqlite3_bind_text(insert.stmt, 3, row.c_str(), -1, SQLITE_TRANSIENT);
      if (sqlite3_step(insert.stmt) != SQLITE_DONE) throw std::runtime_error(sqlite3_errmsg(db_));
      if (sqlite3_changes(db_) == 1)
        ++r.accepted;
      else
        ++r.duplicates;
      sqlite3_reset(insert.stmt);
    }
    Exec("COMMIT");
  } catch (const std::exception& e) {
    sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
    throw std::runtime_error(file_.string() + ": journal: " + e.what());
  }
  return r;
}

void Journal::ForEach(const std::function<void(const std::string&, const std::string&,
                                               const std::string&)>& visit) const {
  Statement select(db_, "SELECT stream, header, row FROM rows ORDER BY seq", file_);
  while (sqlite3_step(select.stmt) == SQLITE_ROW) {
    visit(reinterpret_cast<const char*>(sqlite3_column_text(select.stmt, 0)),
          reinterpret_cast<const char*>(sqlite3_column_text(select.stmt, 1)),
          reinterpret_cast<const char*>(sqlite3_column_text(select.stmt, 2)));
  }
}

std::size_t Journal::size() const {
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
  std::map<std::string, std::ofstream> files;
  ForEach([&](const std::string& stream, const std::string& header, const std::string& row) {
    auto it = files.find(stream);
    if (it == files.end()) {
      it = files.emplace(stream, std::ofstream(dir / stream)).first;
      it->second << header << "\n";
    }
    it->second << row << "\n";
  });
  for (auto& [name, f] : files) {
    f.close();
    if (!f) throw std::runtime_error((dir / name).string() + ": cannot write the export");
  }
}

}  // namespace trailmark::server
