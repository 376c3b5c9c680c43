// What only the SQLite job store does (the rest is job_store_conformance_test.cpp): migrating a file of an older
// schema, refusing a newer one, telling a full disk apart.
#include <gtest/gtest.h>
#include <sqlite3.h>

#include "server/base/job_id.h"
#include "server/store/sqlite_job_store.h"
#include "tests/server/test_util.h"

namespace tessera::server {
namespace {

using test::make_job;

TEST(SqliteJobStore, KeepsTheJobsNameAndGivesOlderJobsAnEmptyOne) {
  test::TempDir dir;
  const auto file = dir.path() / "jobs.db";
  JobRecord old_job = make_job(0, 1), named = make_job(0, 2);
  named.name = "Cornell box, 4096 spp";
  {
    SqliteJobStore store(file);
    store.create(old_job);
  }
  // The file as a daemon of schema version 2 left it: no name column.
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(file.c_str(), &db), SQLITE_OK);
  ASSERT_EQ(
      sqlite3_exec(db,
                   "ALTER TABLE jobs DROP COLUMN name; ALTER TABLE jobs DROP COLUMN epoch; "
                   "ALTER TABLE jobs DROP COLUMN lease_expires_at; ALTER TABLE jobs DROP COLUMN node; "
                   "ALTER TABLE jobs DROP COLUMN lost_runs; DROP TABLE units; ALTER TABLE jobs DROP COLUMN units; "
                   "DELETE FROM schema_version WHERE version >= 3",
                   nullptr, nullptr, nullptr),
      SQLITE_OK)
      << sqlite3_errmsg(db);
  sqlite3_close(db);
  SqliteJobStore store(file);
  store.create(named);
  EXPECT_EQ(store.get(old_job.id, false).value().name, "");
  EXPECT_EQ(store.get(named.id, false).value().name, "Cornell box, 4096 spp");
  EXPECT_EQ(store.claim_next(3).value().name, "");
  EXPECT_EQ(store.list(JobFilter{}).front().name, "Cornell box, 4096 spp");
}

TEST(SqliteJobStore, RefusesANewerSchema) {
  test::TempDir dir;
  const auto file = dir.path() / "jobs.db";
  { SqliteJobStore store(file); }
  // A later daemon migrated the file; this one must not write to it.
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(file.c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, "INSERT INTO schema_version (version) VALUES (99)", nullptr, nullptr, nullptr), SQLITE_OK);
  sqlite3_close(db);
  EXPECT_THROW(SqliteJobStore{file}, JobStoreError);
}

// The file-size limit (EFBIG, or a short write) stands in for a full disk (ENOSPC): SQLite says SQLITE_FULL or an I/O
// error, and either way the store says it ran out of room, so that POST /v1/jobs can answer 507.
TEST(SqliteJobStore, AFullDiskIsAnOutOfSpaceErrorAndStoresNothing) {
  test::TempDir dir;
  SqliteJobStore store(dir.path() / "jobs.db");
  JobRecord big = make_job(0, 1);
  big.document = nlohmann::json{{"kind", "scene"}, {"padding", std::string(1 << 20, 'x')}}.dump();
  {
    test::FileSizeLimit limit(256 << 10);
    try {
      store.create(big);
      ADD_FAILURE() << "a 1 MiB job was stored under a 256 KiB file-size limit";
    } catch (const JobStoreError& e) {
      EXPECT_TRUE(e.out_of_space()) << e.what();
    }
  }
  EXPECT_FALSE(store.get(big.id, false));  // the insert was rolled back whole
  // With room again the store goes on.
  store.create(big);
  EXPECT_EQ(store.get(big.id, true)->document, big.document);
  EXPECT_EQ(store.count_by_state(std::nullopt).at(JobState::kQueued), 1);
}

}  // namespace
}  // namespace tessera::server
