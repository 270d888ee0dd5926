/*
 * The MAVLink checksum (CRC-16/MCRF4XX, "X.25" in MAVLink's sources), slicing
 * by 8: shared by dolphin_crc.c (Dolphin.MAVLink.CRC) and dolphin_native.c
 * (Dolphin.MAVLink.Native). crc16_init() fills the tables once, from
 * the library's load callback.
 */
#ifndef DOLPHIN_CRC16_H
#define DOLPHIN_CRC16_H

#include <stddef.h>
#include <stdint.h>

#define CRC16_POLY 0x8408

static uint16_t crc16_table[8][256];

static void crc16_init(void) {
  for (int b = 0; b < 256; b++) {
    uint16_t crc = (uint16_t)b;
    for (int i = 0; i < 8; i++) crc = (crc & 1) ? (uint16_t)((crc >> 1) ^ CRC16_POLY) : (uint16_t)(crc >> 1);
    crc16_table[0][b] = crc;
  }
  for (int k = 1; k < 8; k++)
    for (int b = 0; b < 256; b++)
      crc16_table[k][b] = (uint16_t)((crc16_table[k - 1][b] >> 8) ^ crc16_table[0][crc16_table[k - 1][b] & 0xFF]);
}

static uint16_t crc16_accumulate(uint16_t crc, const unsigned char *p, size_t n) {
  while (n >= 8) {
    crc = crc16_table[7][(p[0] ^ crc) & 0xFF] ^ crc16_table[6][(p[1] ^ (crc >> 8)) & 0xFF] ^ crc16_table[5][p[2]] ^ crc16_table[4][p[3]] ^
          crc16_table[3][p[4]] ^ crc16_table[2][p[5]] ^ crc16_table[1][p[6]] ^ crc16_table[0][p[7]];
    p += 8;
    n -= 8;
  }
  while (n--) crc = (uint16_t)((crc >> 8) ^ crc16_table[0][(crc ^ *p++) & 0xFF]);
  return crc;
}

static uint16_t crc16_accumulate_byte(uint16_t crc, unsigned byte) {
  return (uint16_t)((crc >> 8) ^ crc16_table[0][(crc ^ byte) & 0xFF]);
}

#endif
