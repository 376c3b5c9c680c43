// The request head as the transport judges it before cpp-httplib parses it (server/http/request_head.h): where it ends,
// what is malformed and known to be as soon as its line has arrived, and when a body is already all there.
#include "server/http/request_head.h"

#include <gtest/gtest.h>

#include <string>

namespace tessera::server {
namespace {

TEST(RequestHead, EndsAtTheFirstEmptyLineAndNotBefore) {
  const std::string head = "POST /v1/jobs?x=1 HTTP/1.1\r\nHost: a\r\nX-Pad: \t b c\t \r\nX-Empty:\r\n\r\n";
  for (size_t cut = 0; cut < head.size(); ++cut) {
    const HeadScan partial = scan_head(std::string_view(head).substr(0, cut));
    EXPECT_EQ(partial.length, 0u) << cut;
    EXPECT_FALSE(partial.problem) << cut;
  }
  // What follows the head (a body with bare LFs and control characters, the next request) is not the head's.
  const std::string bytes = head + "{\n\"a\": \"\x01\"}\nGET";
  const HeadScan scan = scan_head(bytes);
  ASSERT_FALSE(scan.problem) << scan.problem->detail;
  EXPECT_EQ(scan.length, head.size());
  EXPECT_EQ(scan.head.method, "POST");
  EXPECT_EQ(scan.head.target, "/v1/jobs?x=1");
  EXPECT_EQ(scan.head.version, "HTTP/1.1");
  ASSERT_EQ(scan.head.fields.size(), 3u);
  EXPECT_EQ(scan.head.fields[1].first, "X-Pad");
  EXPECT_EQ(scan.head.fields[1].second, "b c");  // optional whitespace around a value is not the value's
  EXPECT_EQ(scan.head.fields[2].second, "");
}

TEST(RequestHead, AMalformedLineIsKnownBeforeTheHeadEnds) {
  for (const std::string bytes :
       {"GET / HTTP/1.1\n", "GET / HTTP/1.1\r\nHost: a\n", "GET / HTTP/1.1\r\n\n", "GET / HTTP/1.1\r\nX-No-Colon\r\n",
        "GET / HTTP/1.1\r\nX-Name : a\r\n", "GET / HTTP/1.1\r\n: a\r\n", "GET / HTTP/1.1\r\nX(a): b\r\n",
        "GET / HTTP/1.1\r\nHost: a\r\n\tfolded\r\n", "GET / HTTP/1.1\r\nX: a\x7f\r\n", "GET / HTTP/1.1\r\nX: a\rb\r\n",
        "GET /a b HTTP/1.1\r\n", "GET /\x01 HTTP/1.1\r\n", "GET / HTTP/11\r\n", "GET / http/1.1\r\n",
        "G@T / HTTP/1.1\r\n", " GET / HTTP/1.1\r\n"}) {
    const HeadScan scan = scan_head(bytes);
    ASSERT_TRUE(scan.problem) << ::testing::PrintToString(bytes);
    EXPECT_EQ(scan.problem->status, 400);
    EXPECT_EQ(scan.length, 0u);
  }
  // Characters above 0x7f are field values (obs-text), and a method is any token: whether it is implemented is not
  // the head's form.
  EXPECT_FALSE(scan_head("BREW / HTTP/1.1\r\nX: caf\xc3\xa9 \xff\r\n\r\n").problem);
}

RequestHead head_of(const std::string& fields) {
  static std::string bytes;  // the views outlive the call
  bytes = "POST / HTTP/1.1\r\nHost: a\r\n" + fields + "\r\n";
  return scan_head(bytes).head;
}

TEST(RequestHead, ABodyHasArrivedOnlyWhenItsLengthIsKnownAndBuffered) {
  EXPECT_TRUE(body_arrived(head_of(""), 0));  // no Content-Length, no Transfer-Encoding: no body
  EXPECT_TRUE(body_arrived(head_of("Content-Length: 0\r\n"), 0));
  EXPECT_TRUE(body_arrived(head_of("content-length: 5\r\n"), 5));
  EXPECT_TRUE(body_arrived(head_of("Content-Length: 5\r\nExpect: 100-continue\r\n"), 5));
  EXPECT_FALSE(body_arrived(head_of("Content-Length: 5\r\n"), 4));
  EXPECT_FALSE(body_arrived(head_of("Content-Length: 5\r\nExpect: 100-continue\r\n"), 0));
  EXPECT_FALSE(body_arrived(head_of("Content-Length: 5\r\nContent-Length: 6\r\n"), 5));
  EXPECT_FALSE(body_arrived(head_of("Transfer-Encoding: chunked\r\n"), 1000));
  // Lengths the API refuses unread (400) are not judged here: such a request waits as a body would.
  EXPECT_FALSE(body_arrived(head_of("Content-Length: 5, 5\r\n"), 5));
  EXPECT_FALSE(body_arrived(head_of("Content-Length: +5\r\n"), 5));
  EXPECT_FALSE(body_arrived(head_of("Content-Length: 99999999999999999999999\r\n"), 5));
}

}  // namespace
// A head that arrives a byte at a time, each scan resuming where the last one's checked lines end, reads as the same
// head, and a malformed line is still refused when it arrives: the lines before it are not read again.
TEST(RequestHead, AScanResumedAtItsCheckedLinesReadsTheSameHead) {
  const std::string head = "POST /v1/jobs HTTP/1.1\r\nHost: x\r\nContent-Length: 2\r\nX-A: b\r\n\r\n{}";
  size_t from = 0;
  HeadScan last;
  for (size_t n = 1; n <= head.size() && last.length == 0; ++n) {
    last = scan_head(std::string_view(head).substr(0, n), from);
    ASSERT_FALSE(last.problem) << n;
    EXPECT_GE(last.checked, from);
    from = last.checked;
  }
  const HeadScan whole = scan_head(head);
  EXPECT_EQ(last.length, whole.length);
  ASSERT_EQ(last.head.fields.size(), 3u);
  EXPECT_EQ(last.head.fields, whole.head.fields);
  EXPECT_EQ(last.head.target, "/v1/jobs");
  const std::string bad = "GET / HTTP/1.1\r\nHost: x\r\nno colon\r\n";
  const HeadScan first = scan_head(std::string_view(bad).substr(0, 25));  // the request line and Host
  EXPECT_EQ(first.checked, 25u);
  EXPECT_TRUE(scan_head(bad, first.checked).problem);
}

}  // namespace tessera::server
