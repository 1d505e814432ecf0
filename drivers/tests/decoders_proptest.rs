//! Every decoder takes any bytes without panicking, and round-trips what its encoder
//! writes. 4096 cases per property.

use proptest::prelude::*;
use softtouch_drivers::ati_serial::codec as ati;
use softtouch_drivers::hande::regs;
use softtouch_drivers::netft::codec as rdt;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4096))]

    #[test]
    fn rdt_records_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let mut out = Vec::new();
        let r = rdt::decode_records(&bytes, &mut out);
        prop_assert_eq!(r.is_ok(), !bytes.is_empty() && bytes.len() % rdt::RECORD_LEN == 0);
        let _ = rdt::decode_request(&bytes);
    }

    #[test]
    fn rdt_records_round_trip(seq in any::<u32>(), ft in any::<u32>(), status in any::<u32>(), counts in any::<[i32; 6]>()) {
        let r = rdt::RawRecord { rdt_sequence: seq, ft_sequence: ft, status, counts };
        prop_assert_eq!(rdt::decode_record(&rdt::encode_record(&r)), Ok(r));
    }

    #[test]
    fn calibration_replies_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..40)) {
        if let Ok(c) = rdt::decode_calibration_reply(&bytes) {
            let _ = c.counts_per_si();
        }
        let _ = rdt::decode_calibration_request(&bytes);
    }

    #[test]
    fn ati_lines_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
        let _ = ati::parse_record(&bytes);
    }

    #[test]
    fn ati_lines_of_digits_and_separators_never_panic(s in "[0-9, \\-+\\r]{0,80}") {
        let _ = ati::parse_record(s.as_bytes());
    }

    #[test]
    fn ati_records_round_trip(error in 0u32..1000, counts in any::<[i32; 6]>()) {
        let r = ati::AsciiRecord { error, counts };
        prop_assert_eq!(ati::parse_record(ati::format_record(&r).as_bytes()), Ok(r));
    }

    #[test]
    fn hande_status_registers_never_panic(words in proptest::collection::vec(any::<u16>(), 0..6)) {
        match regs::decode_status(&words) {
            Ok(s) => {
                prop_assert_eq!(words.len(), 3);
                let _ = (s.object(), s.active(), regs::fault_class(s.g_flt), regs::fault_text(s.g_flt), regs::describe_fault(s.fault_byte()));
            }
            Err(_) => prop_assert_ne!(words.len(), 3),
        }
        let _ = regs::decode_output(&words);
    }

    #[test]
    fn hande_status_round_trips(w in any::<[u16; 3]>()) {
        // Reserved bits (byte 1, bits 1-2 of the status byte) are not kept.
        let s = regs::decode_status(&w).expect("3 words");
        let again = regs::decode_status(&s.encode()).expect("3 words");
        prop_assert_eq!(s, again);
    }
}
