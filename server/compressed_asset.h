// SPDX-License-Identifier: MIT
#pragma once
/// The dashboard's static files compressed once, instead of by the HTTP library on every request
/// (Debian's cpp-httplib 0.11 compresses compressible replies with brotli at quality 11: 0.25 s
/// of CPU for the 164 kB script at every page load, on the machine that runs the incident).

#include <string>
#include <string_view>

namespace trailmark::server {

enum class ContentEncoding { kIdentity, kGzip, kBrotli };

/// The best encoding an Accept-Encoding header allows: brotli, then gzip, else identity. Tokens
/// are matched whole and case-insensitively; a token with q=0 is refused (RFC 9110, 12.5.3).
ContentEncoding PreferredEncoding(std::string_view accept_encoding);
/// The Content-Encoding value ("br", "gzip"; empty for identity).
const char* ContentEncodingName(ContentEncoding encoding);
/// `data` compressed: brotli at quality 11, gzip (RFC 1952) at level 9; identity: a copy.
/// Throws std::runtime_error when the compressor fails.
std::string Compress(std::string_view data, ContentEncoding encoding);

}  // namespace trailmark::server
