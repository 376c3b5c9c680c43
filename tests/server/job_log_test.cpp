// A job's log stays bounded however long its render: the first lines (how it started) and the newest stay, whole,
// with one line saying that lines between were left out; and it lives among the job's files, so that it goes with
// them.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <sstream>
#include <string>
#include <thread>

#include "server/base/job_id.h"
#include "server/files/job_log.h"
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

// Nodes sharing a data volume add to one job's log at once (each renders a unit of it): every line they add is kept,
// and the log reads them in the order of their times. Two logs over two DirectoryJobFiles stand for two nodes.
TEST(JobLog, TwoWritersOfOneLogKeepEveryLine) {
  test::TempDir dir;
  const DirectoryJobFiles a(dir.path()), b(dir.path());
  const std::string id = "0123456789abcdef0123456789abcdef";
  a.prepare(id);
  const JobLog n1(a, "n1"), n2(b, "n2");
  constexpr int kLines = 150;
  std::thread other([&] {
    for (int i = 0; i < kLines; ++i) n2.add(id, "line " + std::to_string(i));
  });
  for (int i = 0; i < kLines; ++i) n1.add(id, "line " + std::to_string(i));
  other.join();
  const std::string log = JobLog::read(b, id).value_or("");
  EXPECT_EQ(std::count(log.begin(), log.end(), '\n'), 2 * kLines) << log;
  EXPECT_NE(log.find("Z  n1  line 149\n"), std::string::npos);
  EXPECT_NE(log.find("Z  n2  line 149\n"), std::string::npos);
  std::string last_time;  // every line's time is at least the one before it
  std::istringstream lines(log);
  for (std::string line; std::getline(lines, line);) {
    const std::string time = line.substr(0, line.find(' '));
    EXPECT_GE(time, last_time) << line;
    last_time = time;
  }
}

// A node that stops in the middle of adding to a job's log (frozen by SIGSTOP, a paused VM) holds up no other node:
// another process (a child, frozen inside its update) and this one add to the same job's log, and this one's line
// is written at once.
TEST(JobLog, AWriterFrozenInTheMiddleOfAnUpdateHoldsUpNoOther) {
  test::TempDir dir;
  const DirectoryJobFiles files(dir.path());
  const std::string id = "0123456789abcdef0123456789abcdef";
  files.prepare(id);
  int ready[2];
  ASSERT_EQ(::pipe(ready), 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    files.update(
        id, JobFile::kLog,
        [&](std::string text) {
          (void)!::write(ready[1], "x", 1);
          ::pause();  // frozen here, whatever the update holds
          return text;
        },
        "n1");
    ::_exit(0);
  }
  char byte;
  ASSERT_EQ(::read(ready[0], &byte, 1), 1);
  std::atomic<bool> written{false};
  std::thread other([&] {
    JobLog(files, "n2").add(id, "unit 2 of 9 done");
    written = true;
  });
  for (int i = 0; i < 100 && !written; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  EXPECT_TRUE(written) << "a line waited 5 s behind another node's frozen update";
  ::kill(child, SIGKILL);
  ::waitpid(child, nullptr, 0);
  other.join();  // released by the child's death, where it was waiting on it
  ::close(ready[0]);
  ::close(ready[1]);
  EXPECT_NE(JobLog::read(files, id).value_or("").find("n2  unit 2 of 9 done"), std::string::npos);
}

}  // namespace
}  // namespace tessera::server
