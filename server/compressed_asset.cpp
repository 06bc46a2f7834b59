// SPDX-License-Identifier: MIT
#include "server/compressed_asset.h"

#include <brotli/encode.h>
#include <zlib.h>

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <stdexcept>

namespace trailmark::server {
namespace {

std::string_view Trim(std::string_view s) {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.remove_prefix(1);
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.remove_suffix(1);
  return s;
}

bool EqualNoCase(std::string_view a, std::string_view b) {
  return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) {
           return std::tolower(static_cast<unsigned char>(x)) ==
                  std::tolower(static_cast<unsigned char>(y));
         });
}

}  // namespace

ContentEncoding PreferredEncoding(std::string_view header) {
  bool br = false, gzip = false;
  while (!header.empty()) {
    const std::size_t comma = header.find(',');
    std::string_view item = header.substr(0, comma);
    header = comma == std::string_view::npos ? std::string_view() : header.substr(comma + 1);
    const std::size_t semi = item.find(';');
    const std::string_view name = Trim(item.substr(0, semi));
    bool allowed = true;
    if (semi != std::string_view::npos) {
      const std::string_view param = Trim(item.substr(semi + 1));
      if (param.size() > 2 && (param[0] == 'q' || param[0] == 'Q') && param[1] == '=') {
        const std::string q(Trim(param.substr(2)));
        char* end = nullptr;
        const double v = std::strtod(q.c_str(), &end);
        allowed = end != q.c_str() && v > 0;
      }
    }
    if (!allowed) continue;
    br = br || EqualNoCase(name, "br");
    gzip = gzip || EqualNoCase(name, "gzip") || EqualNoCase(name, "x-gzip");
  }
  return br ? ContentEncoding::kBrotli : gzip ? ContentEncoding::kGzip : ContentEncoding::kIdentity;
}

const char* ContentEncodingName(ContentEncoding encoding) {
  switch (encoding) {
    case ContentEncoding::kBrotli:
      return "br";
    case ContentEncoding::kGzip:
      return "gzip";
    case ContentEncoding::kIdentity:
      break;
  }
  return "";
}

std::string Compress(std::string_view data, ContentEncoding encoding) {
  if (encoding == ContentEncoding::kBrotli) {
    std::string out(BrotliEncoderMaxCompressedSize(data.size()), '\0');
    std::size_t size = out.size();
    if (out.empty() ||
        !BrotliEncoderCompress(BROTLI_MAX_QUALITY, BROTLI_DEFAULT_WINDOW, BROTLI_MODE_TEXT,
                               data.size(), reinterpret_cast<const uint8_t*>(data.data()), &size,
                               reinterpret_cast<uint8_t*>(out.data())))
      throw std::runtime_error("brotli compression failed");
    out.resize(size);
    return out;
  }
  if (encoding == ContentEncoding::kGzip) {
    z_stream z{};
    // 15 + 16: a gzip header and trailer around the deflate stream.
    if (deflateInit2(&z, 9, Z_DEFLATED, 15 + 16, 9, Z_DEFAULT_STRATEGY) != Z_OK)
      throw std::runtime_error("gzip compression failed");
    std::string out(deflateBound(&z, static_cast<uLong>(data.size())) + 32, '\0');
    z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(data.data()));
    z.avail_in = static_cast<uInt>(data.size());
    z.next_out = reinterpret_cast<Bytef*>(out.data());
    z.avail_out = static_cast<uInt>(out.size());
    const int rc = deflate(&z, Z_FINISH);
    const std::size_t size = z.total_out;
    deflateEnd(&z);
    if (rc != Z_STREAM_END) throw std::runtime_error("gzip compression failed");
    out.resize(size);
    return out;
  }
  return std::string(data);
}

}  // namespace trailmark::server
