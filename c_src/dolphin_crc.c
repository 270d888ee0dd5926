/*
 * The MAVLink checksum (CRC-16/MCRF4XX, "X.25" in MAVLink's sources) for
 * Dolphin.MAVLink.CRC, which falls back to its Erlang implementation when this
 * library cannot be loaded.
 *
 * Why C: a table-driven CRC is a chain of dependent table look-ups. In Erlang
 * each look-up is several checked operations, and the 65,536-entry table that
 * keeps their number down does not stay in the processor's caches on a busy
 * machine; that made the checksum half of the time spent per frame. Here eight
 * 256-entry tables (4 KiB) take eight bytes per step ("slicing by 8"), with
 * independent look-ups.
 *
 * Each call reads at most 280 bytes (a MAVLink frame): far below what a
 * normal scheduler may spend in a NIF. Every offset and length is checked
 * against the binary, so bad arguments raise badarg and never read outside it.
 */
#include <erl_nif.h>
#include <stdint.h>

#define POLY 0x8408

static uint16_t table[8][256];

static int load(ErlNifEnv *env, void **priv_data, ERL_NIF_TERM load_info) {
  (void)env; (void)priv_data; (void)load_info;
  for (int b = 0; b < 256; b++) {
    uint16_t crc = (uint16_t)b;
    for (int i = 0; i < 8; i++) crc = (crc & 1) ? (uint16_t)((crc >> 1) ^ POLY) : (uint16_t)(crc >> 1);
    table[0][b] = crc;
  }
  for (int k = 1; k < 8; k++)
    for (int b = 0; b < 256; b++)
      table[k][b] = (uint16_t)((table[k - 1][b] >> 8) ^ table[0][table[k - 1][b] & 0xFF]);
  return 0;
}

static uint16_t accumulate(uint16_t crc, const unsigned char *p, size_t n) {
  while (n >= 8) {
    crc = table[7][(p[0] ^ crc) & 0xFF] ^ table[6][(p[1] ^ (crc >> 8)) & 0xFF] ^
          table[5][p[2]] ^ table[4][p[3]] ^ table[3][p[4]] ^ table[2][p[5]] ^ table[1][p[6]] ^ table[0][p[7]];
    p += 8;
    n -= 8;
  }
  while (n--) crc = (uint16_t)((crc >> 8) ^ table[0][(crc ^ *p++) & 0xFF]);
  return crc;
}

static uint16_t accumulate_byte(uint16_t crc, unsigned byte) {
  return (uint16_t)((crc >> 8) ^ table[0][(crc ^ byte) & 0xFF]);
}

/* checksum(Binary, Offset, Length, CrcExtra): the CRC from 0xFFFF over Length
 * bytes of Binary from Offset, then the CrcExtra byte. */
static ERL_NIF_TERM checksum(ErlNifEnv *env, int argc, const ERL_NIF_TERM argv[]) {
  ErlNifBinary bin;
  unsigned offset, length, extra;
  (void)argc;
  if (!enif_inspect_binary(env, argv[0], &bin) || !enif_get_uint(env, argv[1], &offset) ||
      !enif_get_uint(env, argv[2], &length) || !enif_get_uint(env, argv[3], &extra) || extra > 255 ||
      (size_t)offset + length > bin.size)
    return enif_make_badarg(env);
  return enif_make_uint(env, accumulate_byte(accumulate(0xFFFF, bin.data + offset, length), extra));
}

/* frame_checksum(Header, MsgId, Payload, Length, CrcExtra): the checksum of a
 * MAVLink 2 frame whose first seven bytes are the little-endian integer Header
 * (magic, len, flags, compat, seq, sysid, compid: the magic is not checksummed),
 * with the 24-bit MsgId and the first Length bytes of Payload. */
static ERL_NIF_TERM frame_checksum(ErlNifEnv *env, int argc, const ERL_NIF_TERM argv[]) {
  ErlNifUInt64 header;
  unsigned msgid, length, extra;
  ErlNifBinary payload;
  unsigned char head[9];
  (void)argc;
  if (!enif_get_uint64(env, argv[0], &header) || !enif_get_uint(env, argv[1], &msgid) || msgid > 0xFFFFFF ||
      !enif_inspect_binary(env, argv[2], &payload) || !enif_get_uint(env, argv[3], &length) ||
      !enif_get_uint(env, argv[4], &extra) || extra > 255 || length > payload.size)
    return enif_make_badarg(env);
  for (int i = 0; i < 6; i++) head[i] = (unsigned char)(header >> (8 * (i + 1)));
  for (int i = 0; i < 3; i++) head[6 + i] = (unsigned char)(msgid >> (8 * i));
  uint16_t crc = accumulate(accumulate(0xFFFF, head, sizeof head), payload.data, length);
  return enif_make_uint(env, accumulate_byte(crc, extra));
}

static ERL_NIF_TERM implementation(ErlNifEnv *env, int argc, const ERL_NIF_TERM argv[]) {
  (void)argc; (void)argv;
  return enif_make_atom(env, "native");
}

static ErlNifFunc functions[] = {
    {"implementation", 0, implementation, 0},
    {"checksum", 4, checksum, 0},
    {"frame_checksum", 5, frame_checksum, 0},
};

ERL_NIF_INIT(Elixir.Dolphin.MAVLink.CRC, functions, load, NULL, NULL, NULL)
