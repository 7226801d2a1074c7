// The vmap::bags component: the one translation unit of a program that holds the MCAP
// library's implementation (MCAP_IMPLEMENTATION, vmap/third_party/mcap) and the decompressors of
// ROS 1 bag chunks (libbz2, liblz4), and hands them to the headers (io/bag/types.hpp,
// detail::bag_component) when the program starts. CMake adds this file to every target
// that links vmap::bags, so link that target into one program (or one shared library)
// only: two copies in one program would define the MCAP library twice.
//
// MCAP (mcap.dev/spec): the magic "\x89MCAP0\r\n", then records `uint8 opcode, uint64
// length, body`: Header, Schema, Channel, Message, Chunk (compression "", "lz4" or
// "zstd"; the records of the data section, compressed), MessageIndex, ..., DataEnd, then
// the summary section (Schema, Channel, Statistics, ChunkIndex, ...), the Footer
// (summary_start) and the magic again. The library parses each record and decompresses
// chunks; the loop over records is ours, so that every length is checked against the
// file and BagLimits before the library allocates for it, and a damaged file ends with
// a warning naming the byte instead of the library's exception or a 4 GB allocation.

#define MCAP_IMPLEMENTATION
#include <mcap/mcap.hpp>

#include <vmap/io/bag/bag.hpp>
#include <vmap/io/bag/detail/file.hpp>
#include <vmap/io/bag/types.hpp>

#include <bzlib.h>
#include <lz4frame.h>
#include <zstd.h>

#include <algorithm>
#include <climits>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <memory>
#include <new>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace {

using vmap::detail::BagConnection;
using vmap::detail::StreamMessage;

/// What one call of a streaming decoder did.
enum class Step { going, ended, failed };

/// Runs a streaming decoder into `out`, which must come to exactly `out_size` bytes (the
/// size a chunk states). `out` grows as output comes, from a first guess of a few times
/// the `in_size` compressed bytes, doubling, never past `out_size`; once it holds
/// `out_size` bytes, one probe byte tells whether the data holds more. So a chunk that
/// states 512 MiB and holds 5 kB costs what its 5 kB decompress to, not a 512 MiB
/// buffer filled with zeros first. `step(dst, room, wrote, why)` decodes into
/// dst[0, room), sets `wrote`, and says whether the data ended, or failed with `why`
/// (corrupt, or cut short: no progress with room to write).
template <class StepFn>
bool decompress_growing(std::size_t in_size, std::size_t out_size, std::string& out, std::string& reason, StepFn step) {
  constexpr std::size_t first_guess = std::size_t{64} << 10;
  out.clear();
  std::size_t produced = 0;
  char probe = 0;
  for (;;) {
    if (produced == out.size() && out.size() < out_size) {
      const std::size_t want = out.empty() ? std::max(first_guess, in_size * 4) : out.size() * 2;
      out.resize(std::min(out_size, want));
    }
    const bool full = produced == out.size();
    std::size_t wrote = 0;
    const Step s = step(full ? &probe : out.data() + produced, full ? std::size_t{1} : out.size() - produced, wrote, reason);
    if (s == Step::failed) return false;
    if (full && wrote > 0) {
      reason = "it decompresses to more than the " + std::to_string(out_size) + " bytes its chunk states";
      return false;
    }
    produced += wrote;
    if (s == Step::ended) break;
  }
  if (produced != out_size) {
    reason = "it decompresses to " + std::to_string(produced) + " bytes, its chunk states " + std::to_string(out_size);
    return false;
  }
  return true;
}

bool bz2_decompress(std::string_view in, std::size_t out_size, std::string& out, std::string& reason) {
  if (in.size() > UINT_MAX) {
    reason = "larger than libbz2 can decompress at once";
    return false;
  }
  bz_stream z{};
  if (BZ2_bzDecompressInit(&z, 0, 0) != BZ_OK) {
    reason = "libbz2 could not start decompressing";
    return false;
  }
  struct End {
    bz_stream& z;
    ~End() { BZ2_bzDecompressEnd(&z); }
  } end{z};
  z.next_in = const_cast<char*>(in.data());
  z.avail_in = static_cast<unsigned int>(in.size());
  return decompress_growing(in.size(), out_size, out, reason, [&](char* dst, std::size_t room, std::size_t& wrote, std::string& why) {
    const auto avail = static_cast<unsigned int>(std::min<std::size_t>(room, UINT_MAX));
    const unsigned int in_before = z.avail_in;
    z.next_out = dst;
    z.avail_out = avail;
    const int rc = BZ2_bzDecompress(&z);
    wrote = avail - z.avail_out;
    if (rc == BZ_STREAM_END) return Step::ended;
    if (rc != BZ_OK) {
      why = rc == BZ_DATA_ERROR         ? "corrupt data (its CRC does not match)"
            : rc == BZ_DATA_ERROR_MAGIC ? "not bz2 data"
            : rc == BZ_MEM_ERROR        ? "not enough memory"
                                        : "libbz2 error " + std::to_string(rc);
      return Step::failed;
    }
    if (wrote == 0 && z.avail_in == in_before) {
      why = "the compressed data is cut short";
      return Step::failed;
    }
    return Step::going;
  });
}

/// An LZ4 frame (roslz4 writes the LZ4 frame format, as MCAP's lz4 chunks hold) into
/// exactly `out_size` bytes.
bool lz4_frame_decompress(std::string_view in, std::size_t out_size, std::string& out, std::string& reason) {
  LZ4F_dctx* ctx = nullptr;
  if (LZ4F_isError(LZ4F_createDecompressionContext(&ctx, LZ4F_VERSION))) {
    reason = "liblz4 could not create a decompression context";
    return false;
  }
  struct End {
    LZ4F_dctx* ctx;
    ~End() { LZ4F_freeDecompressionContext(ctx); }
  } end{ctx};
  std::size_t in_pos = 0;
  const bool ok = decompress_growing(in.size(), out_size, out, reason, [&](char* dst, std::size_t room, std::size_t& wrote, std::string& why) {
    std::size_t src = in.size() - in_pos;
    wrote = room;
    const std::size_t hint = LZ4F_decompress(ctx, dst, &wrote, in.data() + in_pos, &src, nullptr);
    if (LZ4F_isError(hint)) {
      why = std::string("corrupt data (") + LZ4F_getErrorName(hint) + ")";
      return Step::failed;
    }
    in_pos += src;
    if (hint == 0) return Step::ended;
    if (src == 0 && wrote == 0) {
      why = "the LZ4 frame is cut short";
      return Step::failed;
    }
    return Step::going;
  });
  if (ok && in_pos != in.size()) {
    reason = std::to_string(in.size() - in_pos) + " bytes follow the LZ4 frame";
    return false;
  }
  return ok;
}

/// Zstandard data (one or more frames, as MCAP's zstd chunks hold) into exactly
/// `out_size` bytes.
bool zstd_decompress(std::string_view in, std::size_t out_size, std::string& out, std::string& reason) {
  ZSTD_DCtx* ctx = ZSTD_createDCtx();
  if (ctx == nullptr) {
    reason = "libzstd could not create a decompression context";
    return false;
  }
  struct End {
    ZSTD_DCtx* ctx;
    ~End() { ZSTD_freeDCtx(ctx); }
  } end{ctx};
  std::size_t in_pos = 0;
  return decompress_growing(in.size(), out_size, out, reason, [&](char* dst, std::size_t room, std::size_t& wrote, std::string& why) {
    ZSTD_outBuffer o{dst, room, 0};
    ZSTD_inBuffer i{in.data(), in.size(), in_pos};
    const std::size_t left = ZSTD_decompressStream(ctx, &o, &i);
    if (ZSTD_isError(left)) {
      why = std::string("corrupt data (") + ZSTD_getErrorName(left) + ")";
      return Step::failed;
    }
    wrote = o.pos;
    const bool consumed = i.pos > in_pos;
    in_pos = i.pos;
    if (left == 0 && in_pos == in.size()) return Step::ended;  // a frame ended with the data
    if (!consumed && wrote == 0) {
      why = "the zstd data is cut short";
      return Step::failed;
    }
    return Step::going;
  });
}

constexpr std::string_view magic{"\x89MCAP0\r\n", 8};
constexpr std::uint64_t record_head = 9;  // opcode, uint64 length

/// An MCAP time (uint64 nanoseconds) as the signed count every frame time is; nullopt
/// beyond INT64_MAX (the year 2262), which a reader refuses rather than clamps.
std::optional<std::int64_t> as_ns(std::uint64_t t) {
  if (t > static_cast<std::uint64_t>(std::numeric_limits<std::int64_t>::max())) return std::nullopt;
  return static_cast<std::int64_t>(t);
}

/// "time 18446744073.709551615 s", exact, for a time as_ns refuses.
std::string mcap_time_text(std::uint64_t t) {
  std::string frac = std::to_string(t % 1000000000U);
  frac.insert(0, 9 - frac.size(), '0');
  return "time " + std::to_string(t / 1000000000U) + "." + frac + " s";
}

/// An MCAP file's messages, one chunk in memory at a time.
class McapBag final : public vmap::detail::MessageStream {
 public:
  McapBag(const std::filesystem::path& path, const vmap::BagLimits& limits)
      : file_(path, "bag '" + path.string() + "'"), limits_(limits) {
    format_ = vmap::BagFormat::mcap;
    char head[8];
    if (file_.size() < magic.size() || !file_.read(0, head, sizeof head) || std::string_view(head, 8) != magic)
      vmap::detail::fail(vmap::ErrorKind::corrupt, file_.what() + " is not an MCAP file: it does not start with the MCAP magic");
    if (!read_summary()) scan();
    rewind();
  }

  bool next(StreamMessage& out) override {
    Item item;
    while (advance(item))
      if (item.op == mcap::OpCode::Message && wanted(item.message.channelId)) {
        out.connection = item.message.channelId;
        out.record_ns = *as_ns(item.message.logTime);  // advance() returns times in range only
        out.offset = item.offset;
        out.bytes = std::string_view(reinterpret_cast<const char*>(item.message.data),
                                     static_cast<std::size_t>(item.message.dataSize));
        out.owner = std::move(item.owner);
        return true;
      }
    return false;
  }

 private:
  using Bytes = std::vector<std::byte>;
  struct Item {
    mcap::OpCode op = mcap::OpCode::Header;
    mcap::Message message;
    std::shared_ptr<const void> owner;
    std::uint64_t offset = 0;
  };

  /// The opcode and length of the record at `pos`; false and `why` when it does not fit.
  bool record_at(std::uint64_t pos, std::uint8_t& op, std::uint64_t& length, std::string& why) const {
    const std::uint64_t size = file_.size();
    char h[record_head];
    if (pos > size || size - pos < record_head || !file_.read(pos, h, record_head)) {
      why = "the file ends at byte " + std::to_string(size) + ", inside a record's opcode and length";
      return false;
    }
    op = static_cast<std::uint8_t>(h[0]);
    length = vmap::detail::le_u64(h + 1);
    if (length > size - pos - record_head) {
      why = "a record (opcode 0x" + hex(op) + ") claims " + std::to_string(length) + " bytes, the file has " +
            std::to_string(size - pos - record_head) + " left";
      return false;
    }
    return true;
  }

  /// The body of the record at `pos` (its length checked against the limit first).
  std::shared_ptr<Bytes> body_at(std::uint64_t pos, std::uint64_t length, std::string& why) const {
    if (length > limits_.max_chunk_bytes + 4096) {
      why = "a record of " + std::to_string(length) + " bytes, more than the limit of " +
            std::to_string(limits_.max_chunk_bytes) + " (BagLimits::max_chunk_bytes)";
      return nullptr;
    }
    auto body = std::make_shared<Bytes>();
    try {
      body->resize(static_cast<std::size_t>(length));
    } catch (const std::bad_alloc&) {
      why = "not enough memory for a record of " + std::to_string(length) + " bytes";
      return nullptr;
    }
    if (!file_.read(pos + record_head, reinterpret_cast<char*>(body->data()), body->size())) {
      why = "the file ended inside a record";
      return nullptr;
    }
    return body;
  }

  static std::string hex(std::uint8_t v) {
    static const char digits[] = "0123456789abcdef";
    return {digits[v >> 4], digits[v & 15]};
  }

  static mcap::Record record_of(std::uint8_t op, const std::byte* data, std::uint64_t length) {
    return mcap::Record{mcap::OpCode(op), length, const_cast<std::byte*>(data)};
  }

  /// Keeps a schema or channel record (from the summary, the data section or a chunk).
  void keep(const mcap::Record& r) {
    if (r.opcode == mcap::OpCode::Schema) {
      mcap::Schema s;
      if (mcap::McapReader::ParseSchema(r, &s).ok()) schemas_[s.id] = s.name;
    } else if (r.opcode == mcap::OpCode::Channel) {
      mcap::Channel c;
      if (!mcap::McapReader::ParseChannel(r, &c).ok() || channels_.count(c.id) > 0) return;
      const auto s = schemas_.find(c.schemaId);
      channels_[c.id] = BagConnection{c.id, c.topic, s == schemas_.end() ? std::string() : s->second, c.messageEncoding, 0};
    }
  }

  /// Schemas, channels and statistics from the summary section; false when the file has
  /// none (a recording cut short) or it is damaged.
  bool read_summary() {
    const std::uint64_t size = file_.size();
    if (size < magic.size() + mcap::internal::FooterLength) {
      warnings_.push_back(file_.what() + " ends at byte " + std::to_string(size) +
                          " without a footer: the file is truncated; read through to list it");
      return false;
    }
    Bytes tail(mcap::internal::FooterLength);
    if (!file_.read(size - tail.size(), reinterpret_cast<char*>(tail.data()), tail.size())) return false;
    mcap::BufferReader tail_reader;
    tail_reader.reset(tail.data(), tail.size(), tail.size());
    mcap::Footer footer;
    if (!mcap::McapReader::ReadFooter(tail_reader, 0, &footer).ok()) {
      warnings_.push_back(file_.what() + " has no footer at byte " + std::to_string(size - tail.size()) +
                          ": the file is truncated or damaged; read through to list it");
      return false;
    }
    const std::uint64_t footer_at = size - tail.size();
    if (footer.summaryStart == 0) return false;  // written without a summary: read through to list it
    if (footer.summaryStart < magic.size() || footer.summaryStart > footer_at) {
      warnings_.push_back(file_.what() + ": its footer places the summary at byte " + std::to_string(footer.summaryStart) +
                          ", outside the file; read through to list it");
      return false;
    }
    std::optional<mcap::Statistics> stats;
    for (std::uint64_t pos = footer.summaryStart; pos < footer_at;) {
      std::uint8_t op = 0;
      std::uint64_t length = 0;
      std::string why;
      if (!record_at(pos, op, length, why) || pos + record_head + length > footer_at) {
        warnings_.push_back(file_.what() + ": the summary is damaged at byte " + std::to_string(pos) + " (" +
                            (why.empty() ? std::string("a record runs into the footer") : why) + "); read through to list it");
        channels_.clear();
        return false;
      }
      const auto opcode = mcap::OpCode(op);
      if (opcode == mcap::OpCode::Schema || opcode == mcap::OpCode::Channel || opcode == mcap::OpCode::Statistics) {
        const auto body = body_at(pos, length, why);
        if (!body) {
          warnings_.push_back(file_.what() + ": the summary record at byte " + std::to_string(pos) + ": " + why +
                              "; read through to list it");
          channels_.clear();
          return false;
        }
        const mcap::Record r = record_of(op, body->data(), length);
        if (opcode == mcap::OpCode::Statistics) {
          mcap::Statistics s;
          if (mcap::McapReader::ParseStatistics(r, &s).ok()) stats = std::move(s);
        } else {
          keep(r);
        }
      }
      pos += record_head + length;
    }
    if (!stats) {  // a summary without statistics: read through to count the messages
      channels_.clear();
      schemas_.clear();
      return false;
    }
    const auto start = as_ns(stats->messageStartTime), end = as_ns(stats->messageEndTime);
    if (stats->messageCount > 0 && (!start || !end)) {  // a message out of range: read through to skip it
      warnings_.push_back(file_.what() + ": its statistics give a message " +
                          mcap_time_text(start ? stats->messageEndTime : stats->messageStartTime) +
                          ", beyond the range of nanosecond times (the year 2262); read through to list it");
      channels_.clear();
      schemas_.clear();
      return false;
    }
    for (auto& [id, c] : channels_) {
      const auto n = stats->channelMessageCounts.find(id);
      c.messages = n == stats->channelMessageCounts.end() ? 0 : n->second;
      connections_.push_back(c);
    }
    if (stats->messageCount > 0) {
      start_ns_ = *start;
      end_ns_ = *end;
      any_time_ = true;
    }
    indexed_ = true;
    return true;
  }

  /// Reads the file through to find its channels and counts.
  void scan() {
    indexed_ = false;
    channels_.clear();
    rewind();
    Item item;
    std::map<std::uint16_t, std::uint64_t> counts;
    while (advance(item))
      if (item.op == mcap::OpCode::Message) {
        ++counts[item.message.channelId];
        saw_time(*as_ns(item.message.logTime));
      }
    for (auto& [id, c] : channels_) {
      c.messages = counts.count(id) ? counts[id] : 0;
      connections_.push_back(c);
    }
  }

  void rewind() {
    pos_ = magic.size();
    chunk_.reset();
    chunk_pos_ = 0;
    ended_ = false;
  }

  void warn(std::string w) {
    for (const auto& have : warnings_)
      if (have == w) return;
    warnings_.push_back(std::move(w));
  }

  /// The next message (or schema / channel, kept); false at the end.
  bool advance(Item& out) {
    for (;;) {
      if (chunk_) {
        const std::size_t size = chunk_size_;
        if (chunk_pos_ >= size) {
          chunk_.reset();
          continue;
        }
        const std::size_t at = chunk_pos_;
        const std::size_t left = size - at;
        std::uint64_t length = 0;
        if (left < record_head || (length = vmap::detail::le_u64(reinterpret_cast<const char*>(chunk_data_ + at + 1))) >
                                      left - record_head) {
          warn(file_.what() + ": chunk at byte " + std::to_string(chunk_offset_) + ": the record at byte " +
               std::to_string(at) + " of its " + std::to_string(size) +
               " uncompressed bytes runs past its end; the rest of the chunk is skipped");
          chunk_.reset();
          continue;
        }
        chunk_pos_ = at + record_head + static_cast<std::size_t>(length);
        const auto op = static_cast<std::uint8_t>(chunk_data_[at]);
        const mcap::Record r = record_of(op, chunk_data_ + at + record_head, length);
        if (r.opcode == mcap::OpCode::Message) {
          if (!mcap::McapReader::ParseMessage(r, &out.message).ok()) {
            warn(file_.what() + ": chunk at byte " + std::to_string(chunk_offset_) + ": the message record at byte " +
                 std::to_string(at) + " of the chunk is malformed; skipped");
            continue;
          }
          if (!as_ns(out.message.logTime)) {
            warn(file_.what() + ": chunk at byte " + std::to_string(chunk_offset_) + ": the message record at byte " +
                 std::to_string(at) + " of the chunk has log " + mcap_time_text(out.message.logTime) +
                 ", beyond the range of nanosecond times (the year 2262); skipped");
            continue;
          }
          out.op = r.opcode;
          out.owner = chunk_;
          out.offset = chunk_offset_;
          return true;
        }
        keep(r);
        continue;
      }
      if (ended_) return false;
      const std::uint64_t at = pos_;
      if (file_.size() - at == magic.size()) {  // the closing magic of a file without a footer
        ended_ = true;
        continue;
      }
      std::uint8_t op = 0;
      std::uint64_t length = 0;
      std::string why;
      if (!record_at(at, op, length, why)) {
        warn(file_.what() + ": truncated or damaged at byte " + std::to_string(at) + " (" + why +
             "); the messages before it were read");
        ended_ = true;
        continue;
      }
      pos_ = at + record_head + length;
      const auto opcode = mcap::OpCode(op);
      if (opcode == mcap::OpCode::DataEnd || opcode == mcap::OpCode::Footer) {
        ended_ = true;
        continue;
      }
      if (opcode != mcap::OpCode::Chunk && opcode != mcap::OpCode::Message && opcode != mcap::OpCode::Schema &&
          opcode != mcap::OpCode::Channel)
        continue;  // indexes, attachments, metadata: not read
      auto body = body_at(at, length, why);
      if (!body) {
        warn(file_.what() + ": the record at byte " + std::to_string(at) + ": " + why + "; skipped");
        continue;
      }
      const mcap::Record r = record_of(op, body->data(), length);
      if (opcode == mcap::OpCode::Chunk) {
        load_chunk(r, std::move(body), at);
      } else if (opcode == mcap::OpCode::Message) {
        if (!mcap::McapReader::ParseMessage(r, &out.message).ok()) {
          warn(file_.what() + ": the message record at byte " + std::to_string(at) + " is malformed; skipped");
          continue;
        }
        if (!as_ns(out.message.logTime)) {
          warn(file_.what() + ": the message record at byte " + std::to_string(at) + " has log " +
               mcap_time_text(out.message.logTime) + ", beyond the range of nanosecond times (the year 2262); skipped");
          continue;
        }
        out.op = opcode;
        out.owner = std::move(body);
        out.offset = at;
        return true;
      } else {
        keep(r);
      }
    }
  }

  /// The chunk record `r` (body `body`, at byte `at`), decompressed; skipped with a
  /// warning when it cannot be.
  void load_chunk(const mcap::Record& r, std::shared_ptr<Bytes> body, std::uint64_t at) {
    const std::string where = file_.what() + ": chunk at byte " + std::to_string(at);
    mcap::Chunk chunk;
    if (const auto st = mcap::McapReader::ParseChunk(r, &chunk); !st.ok()) {
      warn(where + " is malformed (" + st.message + "); skipped");
      return;
    }
    if (chunk.uncompressedSize > limits_.max_chunk_bytes) {
      warn(where + " claims " + std::to_string(chunk.uncompressedSize) + " uncompressed bytes, more than the limit of " +
           std::to_string(limits_.max_chunk_bytes) + " (BagLimits::max_chunk_bytes); skipped");
      return;
    }
    std::shared_ptr<const void> owner;
    const std::byte* data = nullptr;
    std::size_t size = 0;
    if (chunk.compression.empty()) {
      if (chunk.compressedSize != chunk.uncompressedSize) {
        warn(where + " is uncompressed but states " + std::to_string(chunk.compressedSize) + " and " +
             std::to_string(chunk.uncompressedSize) + " bytes; skipped");
        return;
      }
      data = chunk.records;
      size = static_cast<std::size_t>(chunk.compressedSize);
      owner = std::move(body);
    } else {
      if (chunk.compression != "lz4" && chunk.compression != "zstd") {
        warn(where + " is compressed with '" + chunk.compression + "' (MCAP chunks are lz4, zstd or uncompressed); skipped");
        return;
      }
      auto out = std::make_shared<std::string>();
      const std::string_view compressed(reinterpret_cast<const char*>(chunk.records),
                                        static_cast<std::size_t>(chunk.compressedSize));
      const auto uncompressed = static_cast<std::size_t>(chunk.uncompressedSize);
      std::string reason;
      bool ok = false;
      try {
        ok = chunk.compression == "lz4" ? lz4_frame_decompress(compressed, uncompressed, *out, reason)
                                        : zstd_decompress(compressed, uncompressed, *out, reason);
      } catch (const std::bad_alloc&) {
        reason = "not enough memory";
      }
      if (!ok) {
        warn(where + " does not decompress (" + chunk.compression + ": " + reason + "); skipped");
        return;
      }
      data = reinterpret_cast<const std::byte*>(out->data());
      size = out->size();
      owner = std::move(out);
    }
    if (chunk.uncompressedCrc != 0) {
      const std::uint32_t crc = mcap::internal::crc32Final(mcap::internal::crc32Update(mcap::internal::CRC32_INIT, data, size));
      if (crc != chunk.uncompressedCrc) {
        warn(where + ": its records do not match their CRC (the file is damaged); skipped");
        return;
      }
    }
    chunk_ = std::move(owner);
    chunk_data_ = data;
    chunk_size_ = size;
    chunk_pos_ = 0;
    chunk_offset_ = at;
  }

  vmap::detail::BagFile file_;
  vmap::BagLimits limits_;
  std::map<std::uint16_t, std::string> schemas_;
  std::map<std::uint16_t, BagConnection> channels_;
  std::uint64_t pos_ = 0;
  bool ended_ = false;
  std::shared_ptr<const void> chunk_;
  const std::byte* chunk_data_ = nullptr;
  std::size_t chunk_size_ = 0, chunk_pos_ = 0;
  std::uint64_t chunk_offset_ = 0;
};

std::unique_ptr<vmap::detail::MessageStream> open_mcap(const std::filesystem::path& file, const vmap::BagLimits& limits) {
  return std::make_unique<McapBag>(file, limits);
}

const vmap::detail::BagComponent component{&bz2_decompress, &lz4_frame_decompress, &open_mcap};

[[maybe_unused]] const bool registered = [] {
  vmap::detail::bag_component() = &component;
  return true;
}();

}  // namespace
