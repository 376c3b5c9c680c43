#include <gtest/gtest.h>

#include <set>

#include "server/base/job_id.h"
#include "server/files/assets.h"
#include "server/files/job_files.h"
#include "server/store/job_state.h"
#include "tests/server/test_util.h"

namespace tessera::server {
namespace {

TEST(JobId, NewIdsAreValidAndDistinct) {
  std::set<std::string> seen;
  for (int i = 0; i < 1000; ++i) {
    std::string id = new_job_id();
    EXPECT_TRUE(is_valid_job_id(id)) << id;
    EXPECT_TRUE(seen.insert(id).second);
  }
}

TEST(JobId, RejectsEverythingElse) {
  for (const char* bad :
       {"", "..", "../../etc/passwd", "0123456789abcdef0123456789abcde", "0123456789abcdef0123456789abcdef0",
        "0123456789ABCDEF0123456789ABCDEF", "0123456789abcdef/123456789abcdef",
        "0123456789abcdef\0"
        "123456789abcde",
        "%2e%2e%2f456789abcdef0123456789ab", "0123456789abcdef 123456789abcdef"})
    EXPECT_FALSE(is_valid_job_id(bad)) << bad;
  EXPECT_FALSE(
      is_valid_job_id(std::string_view("0123456789abcdef\0"
                                       "23456789abcdef0",
                                       32)));
}

TEST(JobFiles, PathsStayInsideTheDataDirectory) {
  test::TempDir dir;
  DirectoryJobFiles files(dir.path());
  const std::string id = new_job_id();
  EXPECT_EQ(files.path(id, JobFile::kResultPng), dir.path() / "jobs" / id / "result.png");
  EXPECT_THROW(files.dir("../../etc"), std::invalid_argument);
  EXPECT_THROW(files.path("/etc/passwd", JobFile::kResultExr), std::invalid_argument);
}

TEST(JobFiles, WritesAtomicallyAndRemoves) {
  test::TempDir dir;
  DirectoryJobFiles files(dir.path());
  const std::string id = new_job_id();
  // Writes never create the job's folder (the scheduler makes it when the job starts).
  EXPECT_THROW(files.write(id, JobFile::kPreviewPng, "orphan"), std::runtime_error);
  std::filesystem::create_directories(files.dir(id));
  files.write(id, JobFile::kPreviewPng, "first");
  files.write(id, JobFile::kPreviewPng, "second");
  EXPECT_EQ(files.read(id, JobFile::kPreviewPng), "second");
  // No temporary file is left behind.
  int entries = 0;
  for (const auto& e : std::filesystem::directory_iterator(files.dir(id))) entries += e.is_regular_file();
  EXPECT_EQ(entries, 1);
  files.remove(id);
  EXPECT_FALSE(std::filesystem::exists(files.dir(id)));
  // A late write after removal (a render winding down) does not bring the folder back.
  EXPECT_THROW(files.write(id, JobFile::kPreviewPng, "late"), std::runtime_error);
  EXPECT_FALSE(std::filesystem::exists(files.dir(id)));
}

TEST(JobState, Transitions) {
  EXPECT_TRUE(can_transition(JobState::kQueued, JobState::kRunning));
  EXPECT_TRUE(can_transition(JobState::kQueued, JobState::kCancelled));
  EXPECT_TRUE(can_transition(JobState::kQueued, JobState::kPaused));
  EXPECT_FALSE(can_transition(JobState::kQueued, JobState::kSucceeded));
  EXPECT_TRUE(can_transition(JobState::kRunning, JobState::kQueued));
  EXPECT_TRUE(can_transition(JobState::kRunning, JobState::kPaused));
  EXPECT_TRUE(can_transition(JobState::kRunning, JobState::kFailed));
  EXPECT_TRUE(can_transition(JobState::kPaused, JobState::kQueued));
  EXPECT_TRUE(can_transition(JobState::kPaused, JobState::kCancelled));
  EXPECT_FALSE(can_transition(JobState::kPaused, JobState::kRunning));  // resumed jobs wait their turn
  // Requeue: failed and cancelled jobs may go back to the queue; succeeded is final.
  for (JobState t : {JobState::kFailed, JobState::kCancelled})
    for (JobState to : kAllJobStates) EXPECT_EQ(can_transition(t, to), to == JobState::kQueued);
  for (JobState to : kAllJobStates) EXPECT_FALSE(can_transition(JobState::kSucceeded, to));
  for (JobState s : kAllJobStates) EXPECT_EQ(parse_job_state(job_state_name(s)), s);
  EXPECT_FALSE(parse_job_state("done"));
}

TEST(AssetFileName, NormalisedAssetPathsOnly) {
  for (const char* good : {"scene.gltf", "Box0.bin", "a", "tex_01-b.PNG", "x.y.z", "textures/wood.png",
                           "Normal Map.png", "t\xc3\xa9.png", "100%.png"})
    EXPECT_TRUE(is_asset_file_name(good)) << good;
  EXPECT_TRUE(is_asset_file_name(std::string(255, 'a')));
  EXPECT_FALSE(is_asset_file_name(std::string(256, 'a')));
  for (const char* bad : {"", ".", "..", ".hidden", "../x.bin", "dir/../x.bin", "./x.bin", "dir//x.bin", "/x.bin",
                          "dir/", "dir\\x.bin", "a:b", "x\n.bin", "dir/.asset.json"})
    EXPECT_FALSE(is_asset_file_name(bad)) << bad;
  EXPECT_FALSE(is_asset_file_name(std::string("a\0b", 3)));
}

}  // namespace
}  // namespace tessera::server
