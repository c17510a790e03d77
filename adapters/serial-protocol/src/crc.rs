//! CRC-16/CCITT-FALSE: polynomial 0x1021, initial value 0xFFFF, no reflection, no final XOR.
//!
//! The bitwise form is used rather than a 512-byte table: frames are at most 70 bytes, and a
//! firmware author can check eight lines against the protocol document at a glance.

/// The CRC-16/CCITT-FALSE of `data`; its check value for ASCII `123456789` is 0x29B1.
///
/// ```
/// assert_eq!(serial_protocol::crc16_ccitt_false(b"123456789"), 0x29B1);
/// ```
pub const fn crc16_ccitt_false(data: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    let mut i = 0;
    while i < data.len() {
        crc ^= (data[i] as u16) << 8;
        let mut bit = 0;
        while bit < 8 {
            crc = if crc & 0x8000 != 0 { (crc << 1) ^ 0x1021 } else { crc << 1 };
            bit += 1;
        }
        i += 1;
    }
    crc
}

#[cfg(test)]
mod tests {
    use super::crc16_ccitt_false;

    #[test]
    fn the_check_value_of_the_standard_string_is_0x29b1() {
        assert_eq!(crc16_ccitt_false(b"123456789"), 0x29B1);
    }

    #[test]
    fn the_crc_of_nothing_is_the_initial_value() {
        assert_eq!(crc16_ccitt_false(&[]), 0xFFFF);
    }
}
