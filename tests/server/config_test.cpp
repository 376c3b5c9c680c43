#include <gtest/gtest.h>

#include <map>

#include "server/config.h"

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

}  // namespace
}  // namespace tessera::server
