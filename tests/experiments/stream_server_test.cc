// The viewer's HTTP/WebSocket server (experiments/stream_server.h) through a Beast client on
// localhost: static files and the stream file, the page's report, the live stream (stamps,
// joining at the last keyframe) and bounded buffering for a viewer that does not keep up.
#include "experiments/stream_server.h"

#include <gtest/gtest.h>

#include <boost/asio/connect.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "models/error.h"

namespace artex {
namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = asio::ip::tcp;
namespace fs = std::filesystem;

class StreamServerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("artex_server_test_" + std::to_string(::getpid()));
    fs::create_directories(dir_ / "node_modules/three/build");
    Write(dir_ / "index.html", "<html>viewer</html>");
    Write(dir_ / "node_modules/three/build/three.module.js", "export {};");
    options_.port = 0;
    options_.viewer_dir = dir_.string();
    options_.max_queued_records = 5;
    options_.max_in_flight = 3;
  }
  void TearDown() override { fs::remove_all(dir_); }
  static void Write(const fs::path& p, const std::string& s) {
    std::ofstream(p, std::ios::binary) << s;
  }

  http::response<http::string_body> Request(int port, http::verb verb, const std::string& target,
                                            const std::string& body = "") {
    asio::io_context io;
    tcp::socket socket(io);
    socket.connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), port));
    http::request<http::string_body> req(verb, target, 11);
    req.set(http::field::host, "127.0.0.1");
    req.body() = body;
    req.prepare_payload();
    http::write(socket, req);
    beast::flat_buffer buffer;
    http::response<http::string_body> res;
    http::read(socket, buffer, res);
    return res;
  }

  fs::path dir_;
  StreamServerOptions options_;
};

// A fake record: frame index and keyframe flag (the server does not parse records).
std::vector<uint8_t> Record(uint32_t frame, bool key) {
  std::vector<uint8_t> r(5);
  std::memcpy(r.data(), &frame, 4);
  r[4] = key;
  return r;
}

// A fake keyframe record carrying a rest shape: flag bit 2 of byte 8, as in the container.
std::vector<uint8_t> ShapeRecord(uint32_t frame) {
  std::vector<uint8_t> r = Record(frame, true);
  r.resize(9, 0);
  r[8] = 1 | 4;
  return r;
}

struct Received {
  double stamps[3];
  std::vector<uint8_t> bytes;
};

Received ReadMessage(websocket::stream<tcp::socket>& ws) {
  beast::flat_buffer buffer;
  ws.read(buffer);
  const std::string s = beast::buffers_to_string(buffer.data());
  Received r;
  EXPECT_GE(s.size(), 24u);
  std::memcpy(r.stamps, s.data(), 24);
  r.bytes.assign(s.begin() + 24, s.end());
  return r;
}

uint32_t FrameOf(const Received& r) {
  uint32_t f = 0;
  std::memcpy(&f, r.bytes.data(), 4);
  return f;
}

TEST_F(StreamServerTest, ServesThePageTheStreamFileAndKeepsTheReport) {
  StreamServer server(options_);
  ASSERT_GT(server.port(), 0);
  EXPECT_EQ(Request(server.port(), http::verb::get, "/").body(), "<html>viewer</html>");
  EXPECT_EQ(Request(server.port(), http::verb::get, "/index.html?x=1").result(), http::status::ok);
  EXPECT_EQ(Request(server.port(), http::verb::get, "/../secret").result(),
            http::status::not_found);
  EXPECT_EQ(Request(server.port(), http::verb::get, "/stream.artx").result(),
            http::status::not_found);
  EXPECT_NE(Request(server.port(), http::verb::get, "/info.json").body().find("\"file\":false"),
            std::string::npos);
  Write(dir_ / "s.artx", std::string("ARTX\0\1", 6));
  server.ServeFile((dir_ / "s.artx").string());
  EXPECT_EQ(Request(server.port(), http::verb::get, "/stream.artx").body(),
            std::string("ARTX\0\1", 6));
  EXPECT_FALSE(server.WaitForFinalReport(0.01));
  Request(server.port(), http::verb::post, "/report", "{\"fps\":3,\"done\":true}");
  EXPECT_TRUE(server.WaitForFinalReport(5.0));
  EXPECT_EQ(server.Stats().last_report, "{\"fps\":3,\"done\":true}");
}

TEST_F(StreamServerTest, RejectsBadOptionsAndAMissingPage) {
  StreamServerOptions o = options_;
  o.max_in_flight = 0;
  EXPECT_THROW(StreamServer{o}, Error);
  o = options_;
  o.viewer_dir = (dir_ / "nowhere").string();
  try {
    StreamServer s(o);
    FAIL() << "no error for a missing viewer folder";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("index.html"), std::string::npos) << e.what();
  }
}

// Opens the server's live stream (acknowledgements are text messages).
void ConnectLive(websocket::stream<tcp::socket>* ws, int port) {
  ws->next_layer().connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), port));
  ws->handshake("127.0.0.1", "/live");
  ws->text(true);
}

// Ends the live stream; the server then closes the viewer's connection.
void EndAndExpectClosed(StreamServer* server, websocket::stream<tcp::socket>* ws) {
  server->EndLive();
  beast::flat_buffer rest;
  beast::error_code ec;
  ws->read(rest, ec);
  EXPECT_EQ(ec, websocket::error::closed);
}

TEST_F(StreamServerTest, LiveViewerJoinsAtTheLastKeyframeWithStamps) {
  StreamServer server(options_);
  server.OnHeader({'A', 'R', 'T', 'X'});
  for (uint32_t f = 0; f < 7; ++f)
    server.OnRecord(Record(f, f % 5 == 0), f % 5 == 0, 1000.0 + f, 2000.0 + f);
  asio::io_context io;
  websocket::stream<tcp::socket> ws(io);
  ConnectLive(&ws, server.port());
  const Received header = ReadMessage(ws);
  EXPECT_EQ(header.bytes, std::vector<uint8_t>({'A', 'R', 'T', 'X'}));
  // The records since the last keyframe (5, 6), then the new ones.
  for (uint32_t f : {5u, 6u}) {
    const Received r = ReadMessage(ws);
    EXPECT_EQ(FrameOf(r), f);
    EXPECT_EQ(r.stamps[0], 1000.0 + f);
    EXPECT_EQ(r.stamps[1], 2000.0 + f);
    EXPECT_GE(r.stamps[2], r.stamps[1]);  // published after (wall clock now)
    ws.write(asio::buffer(std::to_string(f - 4)));
  }
  server.OnRecord(Record(7, false), false, 1007.0, 2007.0);
  EXPECT_EQ(FrameOf(ReadMessage(ws)), 7u);
  EndAndExpectClosed(&server, &ws);
  const StreamServerStats s = server.Stats();
  EXPECT_EQ(s.viewers_total, 1);
  EXPECT_EQ(s.records_sent, 3);
  EXPECT_EQ(s.records_dropped, 0);
}

// The rest shape is state: a viewer joining at a keyframe after the record that carried it gets
// that record first (itself a keyframe), then the records since the last keyframe.
TEST_F(StreamServerTest, ALateViewerGetsTheLastRestShapeFirst) {
  StreamServer server(options_);
  server.OnHeader({'A', 'R', 'T', 'X'});
  for (uint32_t f = 0; f < 7; ++f) {
    const bool key = f == 0 || f == 2 || f == 5;
    server.OnRecord(f == 2 ? ShapeRecord(f) : Record(f, key), key, f, f);
  }
  asio::io_context io;
  websocket::stream<tcp::socket> ws(io);
  ConnectLive(&ws, server.port());
  ReadMessage(ws);  // header
  for (uint32_t f : {2u, 5u, 6u}) {
    EXPECT_EQ(FrameOf(ReadMessage(ws)), f);
    ws.write(asio::buffer(std::string("1")));
  }
  EndAndExpectClosed(&server, &ws);
  const StreamServerStats s = server.Stats();
  EXPECT_EQ(s.records_sent, 3);
  EXPECT_EQ(s.records_dropped, 0);
}

TEST_F(StreamServerTest, SlowViewerIsBoundedAndResumesAtAKeyframe) {
  StreamServer server(options_);
  server.OnHeader({'A', 'R', 'T', 'X'});
  asio::io_context io;
  websocket::stream<tcp::socket> ws(io);
  ConnectLive(&ws, server.port());
  ASSERT_TRUE(server.WaitForViewer(10.0));
  // 100 records (keyframes every 4) while the viewer acknowledges nothing.
  const int kRecords = 100, kInterval = 4;
  for (int f = 0; f < kRecords; ++f)
    server.OnRecord(Record(f, f % kInterval == 0), f % kInterval == 0, f, f);
  server.EndLive();
  ReadMessage(ws);  // header
  std::vector<uint32_t> frames;
  for (;;) {
    beast::flat_buffer buffer;
    beast::error_code ec;
    ws.read(buffer, ec);
    if (ec) break;
    Received r;
    const std::string s = beast::buffers_to_string(buffer.data());
    r.bytes.assign(s.begin() + 24, s.end());
    frames.push_back(FrameOf(r));
    ws.write(asio::buffer(std::to_string(frames.size())));
  }
  const StreamServerStats s = server.Stats();
  // Sent: the records in flight and the bounded queue; the rest dropped.
  ASSERT_FALSE(frames.empty());
  EXPECT_LE(static_cast<int>(frames.size()), options_.max_in_flight + options_.max_queued_records);
  EXPECT_EQ(s.records_sent, static_cast<long>(frames.size()));
  EXPECT_EQ(s.records_sent + s.records_dropped, kRecords);
  // Every gap in the frames received is followed by a keyframe (decodable).
  EXPECT_EQ(frames[0] % kInterval, 0u);
  for (std::size_t i = 1; i < frames.size(); ++i) {
    EXPECT_GT(frames[i], frames[i - 1]);
    if (frames[i] != frames[i - 1] + 1) {
      EXPECT_EQ(frames[i] % kInterval, 0u) << "after " << frames[i - 1];
    }
  }
  // It ends with the latest record: the backlog was dropped, not the present.
  EXPECT_EQ(frames.back(), static_cast<uint32_t>(kRecords - 1));
}

}  // namespace
}  // namespace artex
