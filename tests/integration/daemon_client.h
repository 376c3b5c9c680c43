// What the tests of a real tesserad ask of it over HTTP, and of its processes: submit a job, read its status and
// files, and list the daemon's children (its render workers).
#pragma once

#include <sys/types.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <httplib.h>
#include <nlohmann/json.hpp>

namespace tessera::server::test {

// The id of `doc` submitted (a test failure, and "", when it is refused).
inline std::string submit(httplib::Client& c, const nlohmann::json& doc) {
  auto res = c.Post("/v1/jobs", doc.dump(), "application/json");
  if (!res || res->status != 202) {
    ADD_FAILURE() << "not accepted: " << (res ? res->body : "no answer");
    return "";
  }
  return nlohmann::json::parse(res->body).value("id", "");
}

// The job's status; null when there is none.
inline nlohmann::json get_job(httplib::Client& c, const std::string& id) {
  auto res = c.Get("/v1/jobs/" + id);
  if (!res || res->status != 200) return nlohmann::json();
  return nlohmann::json::parse(res->body);
}

inline std::string state_of(httplib::Client& c, const std::string& id) {
  return get_job(c, id).value("state", "");
}

// The body of a GET of `path` (a test failure when it is not a 200).
inline std::string fetch(httplib::Client& c, const std::string& path) {
  auto res = c.Get(path);
  EXPECT_TRUE(res && res->status == 200) << path << ": " << (res ? res->body : "no answer");
  return res ? res->body : "";
}

// The children of `parent` (/proc/PID/stat: the parent's pid is the fourth field, after the parenthesised name).
inline std::vector<pid_t> children_of(pid_t parent) {
  std::vector<pid_t> out;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator("/proc", ec)) {
    const std::string name = entry.path().filename().string();
    if (name.find_first_not_of("0123456789") != std::string::npos) continue;
    std::ifstream in(entry.path() / "stat");
    std::string stat;
    std::getline(in, stat);
    const size_t close = stat.rfind(')');
    if (close == std::string::npos) continue;
    std::istringstream rest(stat.substr(close + 2));
    char state;
    pid_t ppid = 0;
    rest >> state >> ppid;
    if (ppid == parent && state != 'Z') out.push_back(std::stoi(name));
  }
  return out;
}

}  // namespace tessera::server::test
