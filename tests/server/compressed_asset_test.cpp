// SPDX-License-Identifier: MIT
// The dashboard's script compressed once (server/compressed_asset.h): the encoding chosen from
// Accept-Encoding, and the bytes decoded by the reference decoders (brotli's, zlib's) equal to
// the embedded file; served so by a live server.

#include <brotli/decode.h>
#include <zlib.h>

#include <gtest/gtest.h>

#include <chrono>
#include <string>

#include "server/compressed_asset.h"
#include "server/incident_server.h"
#include "server/live_server_fixture.h"

namespace trailmark::server {
namespace {

std::string BrotliDecoded(const std::string& data) {
  std::string out(64 << 20, '\0');
  std::size_t size = out.size();
  EXPECT_EQ(BrotliDecoderDecompress(data.size(), reinterpret_cast<const uint8_t*>(data.data()),
                                    &size, reinterpret_cast<uint8_t*>(out.data())),
            BROTLI_DECODER_RESULT_SUCCESS);
  out.resize(size);
  return out;
}

std::string GzipDecoded(const std::string& data) {
  z_stream z{};
  EXPECT_EQ(inflateInit2(&z, 15 + 16), Z_OK);  // gzip only
  std::string out(64 << 20, '\0');
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(data.data()));
  z.avail_in = static_cast<uInt>(data.size());
  z.next_out = reinterpret_cast<Bytef*>(out.data());
  z.avail_out = static_cast<uInt>(out.size());
  EXPECT_EQ(inflate(&z, Z_FINISH), Z_STREAM_END);
  out.resize(z.total_out);
  inflateEnd(&z);
  return out;
}

TEST(CompressedAsset, TheEncodingIsTheBestTheClientTakes) {
  EXPECT_EQ(PreferredEncoding("gzip, deflate, br"), ContentEncoding::kBrotli);
  EXPECT_EQ(PreferredEncoding("gzip, deflate"), ContentEncoding::kGzip);
  EXPECT_EQ(PreferredEncoding(" GZIP ;q=0.5"), ContentEncoding::kGzip);
  EXPECT_EQ(PreferredEncoding("br;q=0, gzip"), ContentEncoding::kGzip);
  EXPECT_EQ(PreferredEncoding("br;q=0.0, gzip;q=0"), ContentEncoding::kIdentity);
  EXPECT_EQ(PreferredEncoding(""), ContentEncoding::kIdentity);
  EXPECT_EQ(PreferredEncoding("identity"), ContentEncoding::kIdentity);
  EXPECT_EQ(PreferredEncoding("brotli, xgzip"), ContentEncoding::kIdentity);  // whole tokens
}

TEST(CompressedAsset, TheReferenceDecodersGiveTheFileBack) {
  const WebAsset* js = FindWebAsset("/assets/app.js");
  ASSERT_NE(js, nullptr);
  const std::string file(js->content);
  const std::string br = Compress(file, ContentEncoding::kBrotli);
  const std::string gz = Compress(file, ContentEncoding::kGzip);
  EXPECT_LT(br.size(), file.size() / 2);
  EXPECT_LT(gz.size(), file.size() / 2);
  EXPECT_EQ(BrotliDecoded(br), file);
  EXPECT_EQ(GzipDecoded(gz), file);
  EXPECT_EQ(Compress(file, ContentEncoding::kIdentity), file);
  EXPECT_EQ(GzipDecoded(Compress("", ContentEncoding::kGzip)), "");
}

// One GET on a raw socket; the reply's head and body.
std::pair<std::string, std::string> Get(int port, const std::string& path,
                                        const std::string& accept_encoding) {
  Connection c(port);
  EXPECT_TRUE(c.connected());
  std::string request = "GET " + path + " HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n";
  if (!accept_encoding.empty()) request += "Accept-Encoding: " + accept_encoding + "\r\n";
  EXPECT_TRUE(c.Send(request + "\r\n"));
  const std::string reply = c.ReceiveAll(std::chrono::seconds(10));
  const std::size_t end = reply.find("\r\n\r\n");
  EXPECT_NE(end, std::string::npos) << reply.substr(0, 200);
  if (end == std::string::npos) return {reply, ""};
  return {reply.substr(0, end), reply.substr(end + 4)};
}

TEST_F(LiveServerFixture, TheDashboardScriptIsSentCompressedOnceInTheEncodingAsked) {
  const std::string file(FindWebAsset("/assets/app.js")->content);
  for (int round = 0; round < 2; ++round) {  // the second from the cache
    const auto [h_br, b_br] = Get(server_->port(), "/assets/app.js", "gzip, deflate, br");
    EXPECT_NE(h_br.find("Content-Encoding: br"), std::string::npos) << h_br;
    EXPECT_NE(h_br.find("Content-Type: application/javascript; charset=utf-8"), std::string::npos);
    EXPECT_NE(h_br.find("Vary: Accept-Encoding"), std::string::npos);
    EXPECT_EQ(BrotliDecoded(b_br), file);  // once, not twice
    const auto [h_gz, b_gz] = Get(server_->port(), "/assets/app.js", "gzip");
    EXPECT_NE(h_gz.find("Content-Encoding: gzip"), std::string::npos) << h_gz;
    EXPECT_EQ(GzipDecoded(b_gz), file);
    const auto [h_id, b_id] = Get(server_->port(), "/assets/app.js", "");
    EXPECT_EQ(h_id.find("Content-Encoding"), std::string::npos) << h_id;
    EXPECT_EQ(b_id, file);
  }
}

}  // namespace
}  // namespace trailmark::server
