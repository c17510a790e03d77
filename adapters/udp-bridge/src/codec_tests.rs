//! Golden datagrams: bytes in, bytes out.

use super::*;

fn text(v: &[u8]) -> &str {
    std::str::from_utf8(v).expect("utf-8")
}

#[test]
fn numbers_print_like_c_percent_g() {
    for (x, want) in [
        (0.0, "0"),
        (0.1, "0.1"),
        (5000.0, "5000"),
        (1e6, "1e+06"),
        (123456.0, "123456"),
        (1234567.0, "1.23457e+06"),
        (std::f64::consts::PI, "3.14159"),
        (843.5, "843.5"),
        (-0.693099, "-0.693099"),
        (12.449999999999992, "12.45"),
        (0.00001, "1e-05"),
        (0.0001, "0.0001"),
        (100.0, "100"),
        (-180.0, "-180"),
    ] {
        assert_eq!(g(x), want, "{x}");
    }
}

#[test]
fn the_python_clients_registration_decodes_to_four_ir_sensors() {
    // pClient's exact 167 bytes: no NUL, no newline.
    let dg = br#"<Robot Id="1" Name="pClient1"><IRSensor Id="0" Angle="0.0" /><IRSensor Id="1" Angle="60.0" /><IRSensor Id="2" Angle="-60.0" /><IRSensor Id="3" Angle="180.0" /></Robot>"#;
    assert_eq!(dg.len(), 167);
    let Registration::Robot(r) = decode_registration(dg).expect("valid") else { panic!("a robot") };
    assert_eq!((r.name.as_str(), r.id), ("pClient1", 1));
    let angles: Vec<f64> = r.sensors.iter().map(|s| s.angle_deg).collect();
    assert_eq!(angles, [0.0, 60.0, -60.0, 180.0]);
    assert!(r.sensors.iter().all(|s| s.x.is_none() && s.cone_deg.is_none()));
}

#[test]
fn the_thesis_spellings_and_its_repeated_dir_are_accepted() {
    // Thesis Fig. 4.13, DIR twice with the same value, Heigth and COMass.
    let dg = br#"<Robot Name="IntellWheels" Id="1" Width="1.0" Heigth="1.0" DIR="0.0" COMass="0.5" Type="Real" X="13.0" Y="7.0" DIR="0.0" MaxSpeed="0.5" AccelerationCurve="0.7"></Robot>"#;
    let Registration::Robot(r) = decode_registration(dg).expect("valid") else { panic!("a robot") };
    assert_eq!((r.width, r.height, r.com, r.dir), (Some(1.0), Some(1.0), Some(0.5), Some(0.0)));
    assert_eq!(
        (r.kind, r.x, r.y, r.max_speed, r.accel_curve),
        (Some(RobotType::Real), Some(13.0), Some(7.0), Some(0.5), Some(0.7))
    );
    // Thesis Fig. 4.15: Intellwheels sensors with X, Y and Cone.
    let dg = br#"<Robot Name="Teste" Id="1" Width="2.0" Heigth="1.0" DIR="0.0" COM="0.5" X="11.0" Y="11.0"><IRSensor Id="0" X="1.0" Y="0.0" Angle="0.0" Cone="60"/><IRSensor Id="1" X="0.0" Y="0.5" Angle="90" Cone="50"/></Robot>"#;
    let Registration::Robot(r) = decode_registration(dg).expect("valid") else { panic!("a robot") };
    assert_eq!(r.sensors[1], IrSensor { id: 1, x: Some(0.0), y: Some(0.5), angle_deg: 90.0, cone_deg: Some(50.0) });
}

#[test]
fn viewers_panels_and_beacon_robots_register() {
    assert_eq!(decode_registration(b"<View/>\n\0"), Ok(Registration::View));
    assert_eq!(decode_registration(b"<Panel/>"), Ok(Registration::Panel));
    let Ok(Registration::RobotBeacon(r)) = decode_registration(br#"<RobotBeacon Name="b" Id="2" Height="3.5"/>"#)
    else {
        panic!("a beacon robot")
    };
    assert_eq!((r.id, r.beacon_height), (2, Some(3.5)));
}

#[test]
fn malformed_registrations_are_refused_with_their_reason() {
    type Check = fn(&DecodeError) -> bool;
    let cases: &[(&[u8], Check)] = &[
        (b"<Hello/>", |e| matches!(e, DecodeError::UnknownRoot(r) if r == "Hello")),
        (b"<Robot Name=\"a\"", |e| matches!(e, DecodeError::Xml(_))),
        (b"<Robot Id=\"-1\"/>", |e| matches!(e, DecodeError::BadRobotId(v) if v == "-1")),
        (b"<Robot Name=\"n\" Id=\"x\"/>", |e| matches!(e, DecodeError::BadRobotId(v) if v == "x")),
        (b"<RobotBeacon Id=\"1.5\"/>", |e| matches!(e, DecodeError::BadRobotId(v) if v == "1.5")),
        (b"<Robot Width=\"NaN\"/>", |e| matches!(e, DecodeError::BadNumber { .. })),
        (b"<Robot Width=\"1\" Width=\"2\"/>", |e| matches!(e, DecodeError::DuplicateAttribute(a) if a == "Width")),
        (b"<Robot Type=\"Boat\"/>", |e| matches!(e, DecodeError::OutOfRange { .. })),
        (b"<Robot><Wheel/></Robot>", |e| matches!(e, DecodeError::UnknownChild { .. })),
        (b"\xff\xfe\x00junk", |e| matches!(e, DecodeError::NotUtf8 | DecodeError::Empty)),
        (b"", |e| matches!(e, DecodeError::Empty)),
        (b"just text", |e| matches!(e, DecodeError::Empty)),
        (b"<View/><View/>", |e| matches!(e, DecodeError::Xml(_))),
    ];
    for (dg, check) in cases {
        let err = decode_registration(dg).expect_err(&String::from_utf8_lossy(dg));
        assert!(check(&err), "{:?} gave {err:?}", String::from_utf8_lossy(dg));
    }
    let big = vec![b' '; 10 * 1024];
    assert_eq!(decode_registration(&big), Err(DecodeError::TooLong(10 * 1024)));
}

#[test]
fn actions_decode_as_the_stock_clients_send_them() {
    let a = decode_actions(br#"<Actions LeftMotor="0.1" RightMotor="-0.05"/>"#).expect("pClient");
    assert_eq!((a.left, a.right, a.say.as_deref(), a.sync), (Some(0.1), Some(-0.05), None, false));
    let a = decode_actions(b"<Actions><Say><![CDATA[hello world]]></Say></Actions>\n\0").expect("libRobSock say");
    assert_eq!(a.say.as_deref(), Some(&b"hello world"[..]));
    let a = decode_actions(
        b"<Actions>\n\t<SensorRequests IRSensor0=\"Yes\" Compass=\"Yes\" Ground=\"No\" />\n</Actions>\0",
    )
    .expect("requests");
    assert_eq!(a.requests, ["IRSensor0", "Compass"]);
    let a =
        decode_actions(br#"<Actions LeftMotor="0.0" RightMotor="0.0" VisitingLed="On" EndLed="Off"/>"#).expect("leds");
    assert_eq!((a.visiting_led, a.end_led, a.returning_led), (Some(true), Some(false), None));
    let a = decode_actions(br#"<Actions X="10" Y="5" DIR="45"/>"#).expect("real robot pose");
    assert_eq!(a.pose, Some((10.0, 5.0, 45.0)));
    assert!(decode_actions(br#"<Actions LeftMotor="0.1"><Sync/></Actions>"#).expect("sync").sync);
    for bad in [
        &br#"<Actions LeftMotor="nan"/>"#[..],
        br#"<Actions LeftMotor="inf"/>"#,
        b"<Actions><Dance/></Actions>",
        b"<Measures/>",
    ] {
        assert!(decode_actions(bad).is_err(), "{}", String::from_utf8_lossy(bad));
    }
}

#[test]
fn an_attribute_repeated_in_actions_is_malformed_even_with_the_same_value() {
    // The equal-value tolerance is the registration's alone (the thesis's example needs it).
    for bad in [
        &br#"<Actions LeftMotor="0.1" LeftMotor="0.1"/>"#[..],
        br#"<Actions LeftMotor="0.1" RightMotor="0.1" RightMotor="0.15"/>"#,
        br#"<Actions EndLed="On" EndLed="On"/>"#,
        b"<Actions><SensorRequests Compass=\"Yes\" Compass=\"Yes\"/></Actions>",
    ] {
        assert!(
            matches!(decode_actions(bad), Err(DecodeError::DuplicateAttribute(_))),
            "{}",
            String::from_utf8_lossy(bad)
        );
    }
    assert!(matches!(
        decode_viewer(br#"<Robot Id="3" Id="3" Removed="Yes"/>"#),
        Err(DecodeError::DuplicateAttribute(_))
    ));
    assert!(decode_registration(br#"<Robot Name="r" Id="1" Id="1"/>"#).is_ok(), "a registration may repeat a value");
}

#[test]
fn viewer_commands_decode() {
    assert_eq!(decode_viewer(b"<LabReq/>\n\0"), Ok(ViewerCommand::LabReq));
    assert_eq!(decode_viewer(b"<GridReq/>"), Ok(ViewerCommand::GridReq));
    assert_eq!(decode_viewer(b"<Start/>"), Ok(ViewerCommand::Start));
    assert_eq!(decode_viewer(b"<Stop/>"), Ok(ViewerCommand::Stop));
    assert_eq!(decode_viewer(b"<Reset/>"), Ok(ViewerCommand::Reset));
    assert_eq!(decode_viewer(br#"<Robot Id="3" Removed="Yes"/>"#), Ok(ViewerCommand::RemoveRobot(3)));
    assert!(decode_viewer(br#"<Robot Id="3"/>"#).is_err());
}

#[test]
fn the_refusal_is_the_simulators_34_bytes() {
    let r = encode_refused();
    assert_eq!(r, b"<Reply Status=\"Refused\"></Reply>\n\0");
    assert_eq!(r.len(), 34);
}

#[test]
fn the_reply_fits_pclients_buffer_and_carries_what_it_reads() {
    let p = ReplyParams {
        sim_time: 5000,
        cycle_ms: 50,
        compass_noise: 2.0,
        beacon_noise: 2.0,
        obstacle_noise: 0.1,
        motors_noise: 1.5,
        gps: true,
        gps_lin_noise: 0.5,
        gps_dir_noise: 5.0,
        beacon_sensor: false,
        compass_sensor: true,
        n_beacons: 3,
        requests_per_cycle: 4,
        requestable: [true, false, false, true, false],
        latency: [1, 0, 0, 5, 0],
        beacon_aperture: std::f64::consts::PI,
        key_time: 4000,
        scoring: [25, 100, 5, 0, 100, 100],
        score_sensor: true,
    };
    let r = encode_reply_ok(&p);
    assert!(r.len() < 1024, "{} bytes", r.len());
    assert!(r.ends_with(b">\n\0"));
    let t = text(&r);
    for want in [
        "<Reply Status=\"Ok\">",
        "SimTime=\"5000\"",
        "CycleTime=\"50\"",
        "NBeacons=\"3\"",
        "GPS=\"On\"",
        "ObstacleNoise=\"0.1\"",
        "ObstacleRequestable=\"On\"",
        "CompassLatency=\"5\"",
        "RequestsPerCycle=\"4\"",
        "BeaconAperture=\"3.14159\"",
        "KeyTime=\"4000\"",
        "ShowActions=\"True\"",
        "ScoreSensor=\"On\"",
        "ReturnTimePenalty=\"25\" ArrivalTimePenalty=\"100\" CollisionWallPenalty=\"5\" CollisionRobotPenalty=\"0\" TargetReward=\"100\" HomeReward=\"100\"",
    ] {
        assert!(t.contains(want), "{want} missing from {t}");
    }
}

#[test]
fn measures_with_the_defaults_are_byte_exact() {
    let m = MeasuresData {
        time: 4,
        collision: Some(false),
        compass: Some(0.0),
        ground: Some(-1),
        ir: vec![Some(1.4), Some(2.1), Some(2.1), Some(0.6)],
        beacons: vec![],
        gps: None,
        line: Some(0),
        messages: vec![],
        score: None,
        leds: [false; 3],
        buttons: (true, false),
    };
    let want = "<Measures Time=\"4\">\n\t<Sensors Collision=\"No\" Compass=\"0\" Ground=\"-1\">\n\t\t<IRSensor Id=\"0\" Value=\"1.4\"/>\n\t\t<IRSensor Id=\"1\" Value=\"2.1\"/>\n\t\t<IRSensor Id=\"2\" Value=\"2.1\"/>\n\t\t<IRSensor Id=\"3\" Value=\"0.6\"/>\n\t\t<LineSensor Value=\"0000000\" />\n\t</Sensors>\n\t<Leds EndLed=\"Off\" ReturningLed=\"Off\" VisitingLed=\"Off\"/>\n\t<Buttons Start=\"On\" Stop=\"Off\"/>\n</Measures>\n\0";
    assert_eq!(text(&encode_measures(&m)), want);
}

#[test]
fn measures_with_every_sensor_on_are_byte_exact() {
    let m = MeasuresData {
        time: 42,
        collision: Some(true),
        compass: Some(-90.0),
        ground: Some(0),
        ir: vec![Some(100.0), Some(0.3)],
        beacons: vec![Some(Some(180.0)), Some(None)],
        gps: Some((12.345678, 6.1)),
        line: Some(0b1_1100),
        messages: vec![(2, b"hello world".to_vec())],
        score: Some(ScoreData {
            score: -5,
            arrival_time: 56,
            returning_time: 0,
            collisions: 1,
            collision: true,
            visited: 0b10,
            targets: 3,
        }),
        leds: [false, true, true],
        buttons: (false, true),
    };
    let want = "<Measures Time=\"42\">\n\t<Sensors Collision=\"Yes\" Compass=\"-90\" Ground=\"0\">\n\t\t<IRSensor Id=\"0\" Value=\"100\"/>\n\t\t<IRSensor Id=\"1\" Value=\"0.3\"/>\n\t\t<BeaconSensor Id=\"0\" Value=\"180\"/>\n\t\t<BeaconSensor Id=\"1\" Value=\"NotVisible\"/>\n\t\t<GPS X=\"12.3457\" Y=\"6.1\" />\n\t\t<LineSensor Value=\"0011100\" />\n\t\t<Message From=\"2\"><![CDATA[hello world]]></Message>\n\t\t<Score Score=\"-5\" ArrivalTime=\"56\" ReturningTime=\"0\" Collisions=\"1\" Collision=\"True\" VisitedMask=\"010\" />\n\t</Sensors>\n\t<Leds EndLed=\"Off\" ReturningLed=\"On\" VisitingLed=\"On\"/>\n\t<Buttons Start=\"Off\" Stop=\"On\"/>\n</Measures>\n\0";
    assert_eq!(text(&encode_measures(&m)), want);
    // And it comes back through our own decoder as well-formed XML.
    assert!(parse(&encode_measures(&m), Repeats::Refused).is_ok());
}

#[test]
fn viewer_robots_carry_the_intellwheels_body() {
    let r = ViewerRobot {
        name: "r1",
        id: 1,
        time: 42,
        score: ScoreData {
            score: 110,
            arrival_time: 56,
            returning_time: 3,
            collisions: 2,
            collision: false,
            visited: 1,
            targets: 1,
        },
        state: "Returning",
        width: 1.2,
        height: 0.7,
        com: 0.8,
        kind: "Simulated",
        pose: (7.10584, 10.9899, -0.693099),
    };
    let want = "<Robot Name=\"r1\" Id=\"1\" Time=\"42\" Score=\"110\" ArrivalTime=\"56\" ReturningTime=\"3\" Collisions=\"2\" Collision=\"False\" VisitedMask=\"1\" State=\"Returning\" Width=\"1.2\" Height=\"0.7\" CenterOfMovement=\"0.8\" Type=\"Simulated\">\n\t<Position X=\"7.10584\" Y=\"10.9899\" Dir=\"-0.693099\"/>\n</Robot>\n\0";
    assert_eq!(text(&encode_viewer_robot(&r)), want);
}

#[test]
fn lab_and_grid_replies_are_byte_exact() {
    use agent_sdk::map::{Beacon, Circle, GridPose, Point, Wall};
    let l = Map {
        name: "ThesisExampleMap".into(),
        width_m: 28.0,
        height_m: 14.0,
        beacons: vec![Beacon { pos: Point::new(25.0, 7.0), height_m: 30.0 }],
        targets: vec![Circle { pos: Point::new(25.0, 7.0), radius_m: 1.5 }],
        walls: vec![Wall {
            height_m: 2.5,
            corners: vec![Point::new(11.5, 11.5), Point::new(11.5, 2.5), Point::new(13.5, 2.5)],
            obstacle: false,
        }],
        grid: vec![
            GridPose { pos: Point::new(3.0, 11.0), heading_deg: 0.0 },
            GridPose { pos: Point::new(5.0, 7.0), heading_deg: 90.0 },
        ],
        ..Map::default()
    };
    let want = "<Lab Name=\"ThesisExampleMap\" Height=\"14\" Width=\"28\">\n\t<Beacon X=\"25\" Y=\"7\" Height=\"30\"/>\n\t<Target X=\"25\" Y=\"7\" Radius=\"1.5\"/>\n\t<Wall Height=\"2.5\">\n\t\t<Corner X=\"11.5\" Y=\"11.5\"/>\n\t\t<Corner X=\"11.5\" Y=\"2.5\"/>\n\t\t<Corner X=\"13.5\" Y=\"2.5\"/>\n\t</Wall>\n</Lab>\n\0";
    assert_eq!(text(&encode_lab(&l)), want);
    assert_eq!(
        text(&encode_grid(&l)),
        "<Grid>\n\t<Position X=\"3\" Y=\"11\" Dir=\"0\"/>\n\t<Position X=\"5\" Y=\"7\" Dir=\"90\"/>\n</Grid>\n\0"
    );
}

#[test]
fn measures_decode_to_what_was_encoded() {
    let m = MeasuresData {
        time: 1234,
        collision: Some(true),
        compass: Some(-45.0),
        ground: Some(-1),
        ir: vec![Some(2.0), None, Some(0.3), Some(100.0)],
        beacons: vec![Some(Some(12.0)), Some(None)],
        gps: Some((10.5, 3.25)),
        line: None,
        messages: vec![(2, b"hi ]]> there".to_vec())],
        score: Some(ScoreData {
            score: -15,
            arrival_time: 7,
            returning_time: 9,
            collisions: 4,
            collision: false,
            visited: 0b101,
            targets: 3,
        }),
        leds: [false, true, false],
        buttons: (true, false),
    };
    assert_eq!(decode_measures(&encode_measures(&m)), Ok(m));
    let quiet = MeasuresData { time: 7, ..MeasuresData::default() };
    assert_eq!(decode_measures(&encode_measures(&quiet)), Ok(quiet));
}

#[test]
fn a_measures_with_a_bad_number_or_sensor_id_is_refused() {
    assert!(matches!(
        decode_measures(b"<Measures Time=\"1\"><Sensors Compass=\"x\"/></Measures>"),
        Err(DecodeError::BadNumber { .. })
    ));
    let far = b"<Measures Time=\"1\"><Sensors><IRSensor Id=\"99\" Value=\"1\"/></Sensors></Measures>";
    assert!(matches!(decode_measures(far), Err(DecodeError::OutOfRange { .. })));
    assert_eq!(decode_measures(b"<Reply/>"), Err(DecodeError::UnknownRoot("Reply".into())));
}

/// The `%g` the encoder used before it wrote numbers in place (two `String`s per number):
/// every encoded number must come out as it did, byte for byte.
fn g_as_before(x: f64) -> String {
    if x.is_nan() {
        return "nan".into();
    }
    if x.is_infinite() {
        return if x > 0.0 { "inf".into() } else { "-inf".into() };
    }
    if x == 0.0 {
        return "0".into();
    }
    let sci = format!("{x:.5e}");
    let (mant, exp) = sci.split_once('e').unwrap_or((&sci, "0"));
    let exp: i32 = exp.parse().unwrap_or(0);
    let trim = |s: &str| -> String {
        if s.contains('.') { s.trim_end_matches('0').trim_end_matches('.').to_owned() } else { s.to_owned() }
    };
    if !(-4..6).contains(&exp) {
        format!("{}e{}{:02}", trim(mant), if exp < 0 { '-' } else { '+' }, exp.abs())
    } else {
        trim(&format!("{:.*}", (5 - exp).max(0) as usize, x))
    }
}

#[test]
fn numbers_are_written_exactly_as_before_they_were_written_in_place() {
    let mut specials = vec![
        0.0,
        -0.0,
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::MIN_POSITIVE,
        5e-324,
        f64::MAX,
        f64::MIN,
        99999.95,
        999999.5,
        9.999995,
        0.000099999,
        0.00009999995,
        179.99999,
        -179.999995,
    ];
    // Powers of ten and their neighbours (where the exponent form and the rounding turn),
    // then a spread of pseudo-random magnitudes.
    for e in -310..=310 {
        let p = 10f64.powi(e);
        specials.extend([p, -p, p * (1.0 - 5e-7), p * (1.0 + 5e-7), p * 0.999_995, p * 9.999_995]);
    }
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    for _ in 0..20_000 {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        let bits = state;
        let x = f64::from_bits(bits);
        let scaled = (bits >> 11) as f64 / (1u64 << 53) as f64 * 10f64.powi((bits % 40) as i32 - 20);
        specials.extend([x, scaled, -scaled, (scaled * 1e4).round() / 1e4]);
    }
    let mut out = String::new();
    for x in specials {
        out.clear();
        let _ = write!(out, "{}", G(x));
        assert_eq!(out, g_as_before(x), "{x:e} ({:#x})", x.to_bits());
        assert_eq!(g(x), g_as_before(x));
    }
}

#[test]
fn measures_and_viewer_robots_keep_their_bytes() {
    // Expected strings written by the encoder before it wrote numbers in place.
    let m = MeasuresData {
        time: 123456789,
        collision: Some(true),
        compass: Some(-179.99999),
        ground: Some(3),
        ir: vec![None, Some(1.0 / 3.0), Some(99999.95), None, Some(0.000099999)],
        beacons: vec![None, Some(Some(-0.000012345)), Some(None), Some(Some(1234567.0))],
        gps: Some((-1e-300, 5e21)),
        line: None,
        messages: vec![(7, b"a]]>b".to_vec()), (9, vec![0xff, b'x'])],
        score: None,
        leds: [true, false, true],
        buttons: (true, true),
    };
    let want = "<Measures Time=\"123456789\">\n\t<Sensors Collision=\"Yes\" Compass=\"-180\" Ground=\"3\">\n\t\t<IRSensor Id=\"1\" Value=\"0.333333\"/>\n\t\t<IRSensor Id=\"2\" Value=\"99999.9\"/>\n\t\t<IRSensor Id=\"4\" Value=\"9.9999e-05\"/>\n\t\t<BeaconSensor Id=\"1\" Value=\"-1.2345e-05\"/>\n\t\t<BeaconSensor Id=\"2\" Value=\"NotVisible\"/>\n\t\t<BeaconSensor Id=\"3\" Value=\"1.23457e+06\"/>\n\t\t<GPS X=\"-1e-300\" Y=\"5e+21\" />\n\t\t<Message From=\"7\"><![CDATA[a]]]]><![CDATA[>b]]></Message>\n\t\t<Message From=\"9\"><![CDATA[\u{fffd}x]]></Message>\n\t</Sensors>\n\t<Leds EndLed=\"On\" ReturningLed=\"Off\" VisitingLed=\"On\"/>\n\t<Buttons Start=\"On\" Stop=\"On\"/>\n</Measures>\n\0";
    assert_eq!(text(&encode_measures(&m)), want);
    // Into a reused buffer, holding an earlier datagram: the same bytes.
    let mut buf = b"left over from the last tick".to_vec();
    encode_measures_into(&m, &mut buf);
    assert_eq!(text(&buf), want);

    let r = ViewerRobot {
        name: "a&<\"b>",
        id: 77,
        time: 9,
        // A negative score prints unsigned here, as the real simulator prints it.
        score: ScoreData { score: -5, collisions: 3, collision: true, ..ScoreData::default() },
        state: "Stopped",
        width: 0.000099999,
        height: 1e21,
        com: 1.0 / 3.0,
        kind: "Door",
        pose: (99999.95, -0.0, 179.99999),
    };
    let want = "<Robot Name=\"a&amp;&lt;&quot;b&gt;\" Id=\"77\" Time=\"9\" Score=\"4294967291\" ArrivalTime=\"0\" ReturningTime=\"0\" Collisions=\"3\" Collision=\"True\" VisitedMask=\"\" State=\"Stopped\" Width=\"9.9999e-05\" Height=\"1e+21\" CenterOfMovement=\"0.333333\" Type=\"Door\">\n\t<Position X=\"99999.9\" Y=\"0\" Dir=\"180\"/>\n</Robot>\n\0";
    assert_eq!(text(&encode_viewer_robot(&r)), want);
    encode_viewer_robot_into(&r, &mut buf);
    assert_eq!(text(&buf), want);
}
