// Job files under a failing disk: a write that cannot complete (here the file-size limit, EFBIG, standing in for a
// full disk, ENOSPC: both fail write(2) the same way) throws, names the file, leaves the last good version in place
// and no temp file behind.
#include <gtest/gtest.h>

#include <cerrno>
#include <system_error>

#include "server/base/job_id.h"
#include "server/files/job_files.h"
#include "tests/server/test_util.h"

namespace tessera::server {
namespace {

using test::FileSizeLimit;

std::vector<std::string> names_in(const std::filesystem::path& dir) {
  std::vector<std::string> out;
  for (const auto& e : std::filesystem::directory_iterator(dir)) out.push_back(e.path().filename().string());
  return out;
}

TEST(JobFiles, AFailedWriteKeepsTheLastGoodVersion) {
  test::TempDir dir;
  DirectoryJobFiles files(dir.path());
  const std::string id = new_job_id();
  std::filesystem::create_directories(files.dir(id));
  const std::string good(1000, 'a');
  files.write(id, JobFile::kCheckpoint, good);
  {
    FileSizeLimit limit(4096);
    try {
      files.write(id, JobFile::kCheckpoint, std::string(100000, 'b'));
      ADD_FAILURE() << "a write over the limit succeeded";
    } catch (const std::system_error& e) {
      EXPECT_EQ(e.code().value(), EFBIG) << e.what();
      EXPECT_NE(std::string(e.what()).find("cannot write checkpoint.bin"), std::string::npos) << e.what();
    }
    // The same for a staged result.
    EXPECT_THROW(files.stage(id, JobFile::kResultExr, 7, std::string(100000, 'e')), std::system_error);
  }
  EXPECT_EQ(files.read(id, JobFile::kCheckpoint), good);
  EXPECT_EQ(names_in(files.dir(id)), std::vector<std::string>{"checkpoint.bin"});
  // With room again, the next write goes through (a checkpoint is retried at the next pass).
  files.write(id, JobFile::kCheckpoint, std::string(100000, 'c'));
  EXPECT_EQ(files.read(id, JobFile::kCheckpoint)->size(), 100000u);
}

}  // namespace
}  // namespace tessera::server
