#include <gtest/gtest.h>

#include <fstream>
#include <map>

#include "server/config.h"
#include "tests/server/test_util.h"

namespace tessera::server {
namespace {

ConfigResult parse(std::vector<const char*> args, std::map<std::string, std::string> env = {}) {
  args.insert(args.begin(), "tesserad");
  return parse_config(static_cast<int>(args.size()), args.data(), [&](const char* name) -> const char* {
    auto it = env.find(name);
    return it == env.end() ? nullptr : it->second.c_str();
  });
}

TEST(Config, Defaults) {
  auto r = parse({});
  ASSERT_TRUE(r.config);
  EXPECT_EQ(r.config->listen, "127.0.0.1");
  EXPECT_EQ(r.config->port, 8080);
  EXPECT_EQ(r.config->data_dir, "./tessera-data");
  EXPECT_EQ(r.config->threads, 0);
  EXPECT_EQ(r.config->max_jobs, 1);
}

TEST(Config, EnvironmentThenFlags) {
  auto r = parse({"--port", "9000", "--max-jobs=3"},
                 {{"TESSERA_PORT", "7000"}, {"TESSERA_DATA_DIR", "/var/lib/tessera"}, {"TESSERA_MAX_SPP", "128"}});
  ASSERT_TRUE(r.config) << r.error;
  EXPECT_EQ(r.config->port, 9000);  // the flag wins
  EXPECT_EQ(r.config->data_dir, "/var/lib/tessera");
  EXPECT_EQ(r.config->max_jobs, 3);
  EXPECT_EQ(r.config->max_spp, 128u);
}

TEST(Config, TheStoreIsSqliteOrAPostgresUri) {
  EXPECT_EQ(parse({}).config->store, "sqlite");
  auto pg = parse({"--store", "postgresql://tessera@db/tessera", "--node", "render-1"});
  ASSERT_TRUE(pg.config) << pg.error;
  EXPECT_EQ(pg.config->store, "postgresql://tessera@db/tessera");
  EXPECT_EQ(pg.config->node, "render-1");
  EXPECT_TRUE(parse({}, {{"TESSERA_STORE", "postgres:///tessera?host=/run/postgresql"}}).config);
  EXPECT_FALSE(parse({"--node", "../x"}).config);  // it names a lock file in the data directory
  EXPECT_FALSE(parse({"--node", ""}).config);
  auto wrong = parse({"--store", "mysql://db/tessera"});
  EXPECT_FALSE(wrong.config);
  EXPECT_NE(wrong.error.find("--store must be sqlite or a PostgreSQL URI"), std::string::npos) << wrong.error;
}

TEST(Config, Errors) {
  EXPECT_FALSE(parse({"--port", "70000"}).config);
  EXPECT_FALSE(parse({"--port", "80x"}).config);
  EXPECT_FALSE(parse({"--threads"}).config);
  EXPECT_FALSE(parse({"--frobnicate", "1"}).config);
  EXPECT_FALSE(parse({"--log-level", "loud"}).config);
  EXPECT_FALSE(parse({}, {{"TESSERA_MAX_JOBS", "0"}}).config);
  EXPECT_TRUE(parse({"--help"}).help);
  EXPECT_NE(config_usage().find("TESSERA_PORT"), std::string::npos);
}

TEST(Config, StorageDefaults) {
  auto r = parse({});
  ASSERT_TRUE(r.config);
  EXPECT_EQ(r.config->min_free_disk_bytes, 256ull << 20);
  EXPECT_EQ(r.config->retain_finished_s, 0);
}

TEST(Config, ByteSizes) {
  const std::pair<const char*, uint64_t> valid[] = {
      {"0", 0},
      {"268435456", 268435456},
      {"512MiB", 512ull << 20},
      {"2GiB", 2ull << 30},
      {"1G", 1000000000},
      {"1GB", 1000000000},
      {"1g", 1000000000},
      {"10K", 10000},
      {"10KiB", 10240},
      {"7B", 7},
      {"3T", 3000000000000},
      {"1000TiB", 1000ull << 40},
      {"16383PiB", 16383ull << 50},
      {"18446744073709551615", 18446744073709551615ull},
  };
  for (const auto& [text, bytes] : valid) {
    std::string error;
    auto n = parse_byte_size(text, &error);
    ASSERT_TRUE(n) << text << ": " << error;
    EXPECT_EQ(*n, bytes) << text;
  }
  for (const char* text : {"", "MiB", "-1", "1.5GiB", "12XB", "2 GiB", "2GiBs", "0x10", " 5", "1e9"}) {
    std::string error;
    EXPECT_FALSE(parse_byte_size(text, &error)) << text;
    EXPECT_NE(error.find("must be a size"), std::string::npos) << text << ": " << error;
  }
  for (const char* text : {"18446744073709551616", "16384PiB", "20000000000T", "99999999999999999999999"}) {
    std::string error;
    EXPECT_FALSE(parse_byte_size(text, &error)) << text;
    EXPECT_NE(error.find("too large"), std::string::npos) << text << ": " << error;
  }
}

TEST(Config, Durations) {
  const std::pair<const char*, int64_t> valid[] = {
      {"0", 0},       {"90", 90},       {"90s", 90}, {"15m", 900},
      {"12h", 43200}, {"30d", 2592000}, {"0d", 0},   {"36500d", 3153600000}};
  for (const auto& [text, seconds] : valid) {
    std::string error;
    auto n = parse_duration_s(text, &error);
    ASSERT_TRUE(n) << text << ": " << error;
    EXPECT_EQ(*n, seconds) << text;
  }
  for (const char* text : {"", "d", "-5s", "1.5h", "2w", "10 s", "3D", "1h30m", "forever"}) {
    std::string error;
    EXPECT_FALSE(parse_duration_s(text, &error)) << text;
    EXPECT_NE(error.find("must be a duration"), std::string::npos) << text << ": " << error;
  }
  for (const char* text : {"36501d", "3153600001", "99999999999999999999d", "18446744073709551615s"}) {
    std::string error;
    EXPECT_FALSE(parse_duration_s(text, &error)) << text;
    EXPECT_NE(error.find("too long"), std::string::npos) << text << ": " << error;
  }
}

TEST(Config, StorageSettingsFromFlagsEnvironmentAndFile) {
  auto r = parse({"--min-free-disk", "2GiB", "--retain-finished=12h"});
  ASSERT_TRUE(r.config) << r.error;
  EXPECT_EQ(r.config->min_free_disk_bytes, 2ull << 30);
  EXPECT_EQ(r.config->retain_finished_s, 43200);

  r = parse({}, {{"TESSERA_MIN_FREE_DISK", "0"}, {"TESSERA_RETAIN_FINISHED", "30d"}});
  ASSERT_TRUE(r.config) << r.error;
  EXPECT_EQ(r.config->min_free_disk_bytes, 0u);
  EXPECT_EQ(r.config->retain_finished_s, 30 * 86400);

  test::TempDir dir;
  const auto file = dir.path() / "tesserad.json";
  std::ofstream(file) << R"({"min-free-disk": "1G", "retain_finished": 90})";
  r = parse({"--config", file.c_str()});
  ASSERT_TRUE(r.config) << r.error;
  EXPECT_EQ(r.config->min_free_disk_bytes, 1000000000u);
  EXPECT_EQ(r.config->retain_finished_s, 90);
  // A flag wins over the file.
  r = parse({"--config", file.c_str(), "--retain-finished", "0"});
  ASSERT_TRUE(r.config) << r.error;
  EXPECT_EQ(r.config->retain_finished_s, 0);
}

TEST(Config, StorageSettingErrorsNameTheSetting) {
  auto r = parse({"--min-free-disk", "lots"});
  ASSERT_FALSE(r.config);
  EXPECT_EQ(r.error.rfind("--min-free-disk must be a size", 0), 0u) << r.error;
  r = parse({"--min-free-disk", "99999999PiB"});
  ASSERT_FALSE(r.config);
  EXPECT_EQ(r.error.rfind("--min-free-disk is too large", 0), 0u) << r.error;
  r = parse({}, {{"TESSERA_RETAIN_FINISHED", "1w"}});
  ASSERT_FALSE(r.config);
  EXPECT_EQ(r.error.rfind("TESSERA_RETAIN_FINISHED must be a duration", 0), 0u) << r.error;

  test::TempDir dir;
  const auto file = dir.path() / "tesserad.json";
  std::ofstream(file) << R"({"retain-finished": "99999d"})";
  r = parse({"--config", file.c_str()});
  ASSERT_FALSE(r.config);
  EXPECT_NE(r.error.find("\"retain-finished\" is too long"), std::string::npos) << r.error;
}

TEST(Config, AMisspeltOptionOrKeyNamesTheClosestOne) {
  auto r = parse({"--max-job", "2"});
  ASSERT_FALSE(r.config);
  EXPECT_EQ(r.error, "unknown option --max-job (did you mean \"--max-jobs\"?)");
  EXPECT_EQ(parse({"--frobnicate", "1"}).error, "unknown option --frobnicate");  // nothing close
  EXPECT_TRUE(parse({"--version"}).version);

  test::TempDir dir;
  const auto file = dir.path() / "tesserad.json";
  std::ofstream(file) << R"({"max_job": 2})";
  r = parse({"--config", file.c_str()});
  ASSERT_FALSE(r.config);
  EXPECT_NE(r.error.find(": unknown key \"max_job\" (did you mean \"max-jobs\"?)"), std::string::npos) << r.error;
}

}  // namespace
}  // namespace tessera::server
