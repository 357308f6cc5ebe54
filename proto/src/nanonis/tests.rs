use super::*;

#[test]
fn a_request_header_is_forty_bytes_big_endian_with_the_name_padded() {
    let bytes = encode_request("FolMe.XYPosSet", &[1, 2, 3], true).unwrap();
    assert_eq!(bytes.len(), HEADER_LEN + 3);
    assert_eq!(&bytes[..14], b"FolMe.XYPosSet");
    assert!(bytes[14..32].iter().all(|&b| b == 0));
    assert_eq!(&bytes[32..36], &[0, 0, 0, 3]);
    assert_eq!(&bytes[36..40], &[0, 1, 0, 0]);
    let h = decode_request_header(bytes[..HEADER_LEN].try_into().unwrap()).unwrap();
    assert_eq!(
        h,
        RequestHeader {
            name: "FolMe.XYPosSet".into(),
            body_size: 3,
            send_response: true
        }
    );
}

#[test]
fn a_response_header_round_trips_and_refuses_bad_padding() {
    let bytes = encode_response("ZCtrl.Withdraw", &[0; 8]).unwrap();
    let mut h: [u8; HEADER_LEN] = bytes[..HEADER_LEN].try_into().unwrap();
    assert_eq!(
        decode_response_header(&h).unwrap(),
        ResponseHeader {
            name: "ZCtrl.Withdraw".into(),
            body_size: 8
        }
    );
    h[39] = 7;
    assert!(matches!(decode_response_header(&h), Err(FrameError::BadHeader { .. })));
}

#[test]
fn names_that_do_not_fit_the_header_are_refused() {
    assert!(encode_request("", &[], true).is_err());
    assert!(encode_request(&"x".repeat(33), &[], true).is_err());
    assert!(encode_request("Scan\0Action", &[], true).is_err());
    assert!(encode_request(&"x".repeat(32), &[], true).is_ok());
}

#[test]
fn a_negative_or_huge_body_size_is_refused() {
    let mut h = [0u8; HEADER_LEN];
    h[..4].copy_from_slice(b"Scan");
    h[32..36].copy_from_slice(&(-1i32).to_be_bytes());
    let e = decode_response_header(&h).unwrap_err().to_string();
    assert!(e.contains("body size -1"), "{e}");
    h[32..36].copy_from_slice(&i32::MAX.to_be_bytes());
    assert!(decode_response_header(&h).is_err());
}

#[test]
fn a_garbage_name_is_refused() {
    let mut h = [0u8; HEADER_LEN];
    h[..3].copy_from_slice(&[0xff, b'a', b'b']);
    assert!(decode_response_header(&h).is_err());
    let mut h = [0u8; HEADER_LEN];
    h[..5].copy_from_slice(b"ab\0cd");
    assert!(decode_response_header(&h).is_err(), "bytes after the NUL padding");
}

#[test]
fn body_fields_round_trip() {
    let mut w = BodyWriter::new();
    w.i32(-5)
        .u32(7)
        .u16(3)
        .f32(1.5)
        .f64(-2.25e-9)
        .string("Z (m)")
        .f32s(&[1.0, 2.0]);
    ErrorBlock::ok().write(&mut w);
    let bytes = w.into_bytes();
    let mut r = BodyReader::new(&bytes);
    assert_eq!(r.i32("a").unwrap(), -5);
    assert_eq!(r.u32("b").unwrap(), 7);
    assert_eq!(r.u16("c").unwrap(), 3);
    assert_eq!(r.f32("d").unwrap(), 1.5);
    assert_eq!(r.f64("e").unwrap(), -2.25e-9);
    assert_eq!(r.string("f").unwrap(), "Z (m)");
    assert_eq!(r.f32s("g", 2).unwrap(), vec![1.0, 2.0]);
    let e = ErrorBlock::read(&mut r).unwrap();
    assert!(!e.is_error());
}

#[test]
fn a_short_body_names_the_field_and_the_offset() {
    let bytes = [0u8, 0, 0, 1, 0, 0];
    let mut r = BodyReader::new(&bytes);
    r.i32("count").unwrap();
    let e = r.f64("X (m)").unwrap_err().to_string();
    assert_eq!(e, "body too short: X (m) needs 8 bytes at offset 4, the body has 6");
}

#[test]
fn lying_counts_are_refused_without_allocating() {
    let mut w = BodyWriter::new();
    w.i32(i32::MAX);
    let bytes = w.into_bytes();
    assert!(BodyReader::new(&bytes).string("name").is_err());
    assert!(BodyReader::new(&bytes).strings("names", 1 << 40).is_err());
    assert!(BodyReader::new(&bytes).f32s("data", usize::MAX / 2).is_err());
}

#[test]
fn an_error_block_alone_is_recognised_with_its_text() {
    let mut w = BodyWriter::new();
    ErrorBlock {
        status: 1,
        description: "Z-Controller is off".into(),
    }
    .write(&mut w);
    let bytes = w.into_bytes();
    let e = ErrorBlock::alone(&bytes).unwrap();
    assert!(e.is_error());
    assert_eq!(e.description, "Z-Controller is off");
    assert!(ErrorBlock::alone(&bytes[..bytes.len() - 1]).is_none());
}

#[test]
fn a_logger_frame_round_trips_and_a_bad_count_is_refused() {
    let f = LoggerFrame {
        oversampling: 10.0,
        counter: 42,
        state: 1,
        values: vec![0.5, -1.0e-9, 3.0],
    };
    let bytes = f.encode();
    assert_eq!(bytes.len(), LOGGER_HEADER_LEN + 12);
    assert_eq!(LoggerFrame::decode(&bytes).unwrap(), f);
    let header: [u8; LOGGER_HEADER_LEN] = bytes[..LOGGER_HEADER_LEN].try_into().unwrap();
    assert_eq!(LoggerFrame::channels_in_header(&header).unwrap(), 3);
    let mut bad = header;
    bad[..4].copy_from_slice(&1000u32.to_be_bytes());
    assert!(LoggerFrame::channels_in_header(&bad).is_err());
}
