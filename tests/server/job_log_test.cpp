// A job's log stays bounded however long its render: the first lines (how it started) and the newest stay, whole,
// with one line saying that lines between were left out; and it lives among the job's files, so that it goes with
// them.
#include <gtest/gtest.h>

#include <string>

#include "server/job_id.h"
#include "server/job_log.h"
#include "tests/server/test_util.h"

namespace tessera::server {
namespace {

size_t count(const std::string& text, const std::string& what) {
  size_t n = 0;
  for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

TEST(JobLog, KeepsItsFirstAndNewestLinesWithinItsBound) {
  std::string log;
  for (int i = 0; i < 5000; ++i) log = append_bounded(std::move(log), "pass " + std::to_string(i) + ": 1/5000 spp");
  EXPECT_LE(log.size(), kMaxLogBytes);
  EXPECT_GT(log.size(), kMaxLogBytes - 64);  // the room is used
  EXPECT_EQ(log.rfind("pass 0: 1/5000 spp\npass 1: ", 0), 0u) << log.substr(0, 100);
  EXPECT_TRUE(log.ends_with("\npass 4999: 1/5000 spp\n"));
  EXPECT_EQ(count(log, "[earlier lines left out"), 1u);
  // Whole lines only: every line is a pass or the marker.
  size_t start = 0;
  while (start < log.size()) {
    const size_t end = log.find('\n', start);
    ASSERT_NE(end, std::string::npos);
    const std::string line = log.substr(start, end - start);
    EXPECT_TRUE(line.rfind("pass ", 0) == 0 || line.rfind("[earlier lines left out", 0) == 0) << line;
    start = end + 1;
  }
  // The head is the first lines up to kLogHeadBytes; the marker follows it.
  const size_t marker = log.find("[earlier");
  EXPECT_LE(marker, kLogHeadBytes);
  EXPECT_GT(marker, kLogHeadBytes - 32);
}

TEST(JobLog, ALineLongerThanTheBoundIsCutToIt) {
  const std::string log = append_bounded("first\n", std::string(3000, 'x'), 1000, 100);
  EXPECT_LE(log.size(), 1000u);
  EXPECT_EQ(log.rfind("first\n[earlier lines left out", 0), 0u);
}

TEST(JobLog, IsWrittenAmongTheJobsFilesOnceItHasThem) {
  test::TempDir dir;
  DirectoryJobFiles files(dir.path());
  JobLog log(files);
  const std::string id = new_job_id();
  log.add(id, "before it started");  // no place yet: nothing, and no error
  EXPECT_FALSE(files.read(id, JobFile::kLog));
  files.prepare(id);
  log.add(id, "scene loaded in 0.1 s");
  log.add(id, "pass 1: 1/1 spp");
  const std::string text = files.read(id, JobFile::kLog).value();
  EXPECT_EQ(count(text, "\n"), 2u);
  EXPECT_NE(text.find("Z  scene loaded in 0.1 s\n"), std::string::npos) << text;
  EXPECT_TRUE(text.ends_with("Z  pass 1: 1/1 spp\n")) << text;
  files.remove(id);
  EXPECT_FALSE(files.read(id, JobFile::kLog));
}

}  // namespace
}  // namespace tessera::server
