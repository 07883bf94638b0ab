//! Property tests of the CAN protocol: encode/decode round trips and total decoding.

use proptest::prelude::*;
use vge_bridge::protocol::*;

fn finger() -> impl Strategy<Value = FingerId> {
    (0..MAX_FINGERS).prop_map(|i| FingerId::new(i).expect("in range"))
}

fn triple(max: f32) -> impl Strategy<Value = [f32; 3]> {
    [-max..max, -max..max, -max..max]
}

fn message() -> impl Strategy<Value = Message> {
    prop_oneof![
        (finger(), triple(3.2), any::<bool>(), any::<u8>()).prop_map(|(finger, q, enable, seq)| {
            Message::JointCommand(JointCommand { finger, q_target_rad: q, enable, seq })
        }),
        (finger(), triple(3.2), 0u8..4, any::<u8>()).prop_map(|(finger, q, status, seq)| {
            Message::JointPosition(JointPosition { finger, q_rad: q, status, seq })
        }),
        (finger(), triple(30.0), any::<u8>()).prop_map(|(finger, dq, seq)| Message::JointVelocity(
            JointVelocity { finger, dq_radps: dq, seq }
        )),
        (finger(), triple(3.2), any::<u8>())
            .prop_map(|(finger, tau, seq)| Message::JointEffort(JointEffort { finger, tau_nm: tau, seq })),
        (finger(), triple(0.5), 0.0f32..60.0).prop_map(|(finger, p, force_n)| {
            Message::TipContact(TipContact { finger, position_m: p, force_n })
        }),
        (finger(), triple(1.0), any::<bool>(), any::<u8>()).prop_map(|(finger, n, in_contact, seq)| {
            Message::TipNormal(TipNormal { finger, normal: n, in_contact, seq })
        }),
        (finger(), triple(3.2), any::<u8>()).prop_map(|(finger, q, seq)| {
            Message::JointTarget(JointTarget { finger, q_target_rad: q, seq })
        }),
        (prop_oneof![0u8..MAX_FINGERS, Just(HOST_NODE)], 0usize..4, any::<u8>()).prop_map(
            |(node, s, counter)| {
                let state = [NodeState::Booting, NodeState::Ready, NodeState::Enabled, NodeState::Fault][s];
                Message::Heartbeat(Heartbeat { node, state, counter })
            }
        ),
        (finger(), 0usize..5, prop::option::of(0u8..3), any::<i16>(), any::<u8>()).prop_map(
            |(finger, code, joint, value, seq)| {
                let code = [
                    FaultCode::OverTemperature,
                    FaultCode::OverCurrent,
                    FaultCode::EncoderError,
                    FaultCode::CommandTimeout,
                    FaultCode::JointLimit,
                ][code];
                Message::Fault(Fault { finger, code, joint, value, seq })
            }
        ),
    ]
}

/// Largest difference between the float fields of two messages of the same kind, in units
/// of that field's count; `None` if kinds, fingers, flags or counters differ.
fn max_error_in_counts(a: &Message, b: &Message) -> Option<f32> {
    fn err(x: &[f32], y: &[f32], scale: f32) -> f32 {
        x.iter().zip(y).map(|(p, q)| (p - q).abs() / scale).fold(0.0, f32::max)
    }
    match (a, b) {
        (Message::JointCommand(x), Message::JointCommand(y)) => {
            (x.finger == y.finger && x.enable == y.enable && x.seq == y.seq)
                .then(|| err(&x.q_target_rad, &y.q_target_rad, ANGLE_RAD_PER_COUNT))
        }
        (Message::JointPosition(x), Message::JointPosition(y)) => {
            (x.finger == y.finger && x.status == y.status && x.seq == y.seq)
                .then(|| err(&x.q_rad, &y.q_rad, ANGLE_RAD_PER_COUNT))
        }
        (Message::JointVelocity(x), Message::JointVelocity(y)) => (x.finger == y.finger && x.seq == y.seq)
            .then(|| err(&x.dq_radps, &y.dq_radps, VELOCITY_RADPS_PER_COUNT)),
        (Message::JointEffort(x), Message::JointEffort(y)) => {
            (x.finger == y.finger && x.seq == y.seq).then(|| err(&x.tau_nm, &y.tau_nm, EFFORT_NM_PER_COUNT))
        }
        (Message::TipContact(x), Message::TipContact(y)) => (x.finger == y.finger).then(|| {
            err(&x.position_m, &y.position_m, POSITION_M_PER_COUNT).max(err(
                &[x.force_n],
                &[y.force_n],
                FORCE_N_PER_COUNT,
            ))
        }),
        (Message::TipNormal(x), Message::TipNormal(y)) => {
            (x.finger == y.finger && x.in_contact == y.in_contact && x.seq == y.seq)
                .then(|| err(&x.normal, &y.normal, NORMAL_PER_COUNT))
        }
        (Message::JointTarget(x), Message::JointTarget(y)) => (x.finger == y.finger && x.seq == y.seq)
            .then(|| err(&x.q_target_rad, &y.q_target_rad, ANGLE_RAD_PER_COUNT)),
        (Message::Heartbeat(x), Message::Heartbeat(y)) => (x == y).then_some(0.0),
        (Message::Fault(x), Message::Fault(y)) => (x == y).then_some(0.0),
        _ => None,
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4000))]

    #[test]
    fn every_message_round_trips_to_within_half_a_count(m in message()) {
        let frame = m.encode().expect("values are in range");
        let back = Message::decode_frame(&frame).expect("own frames decode");
        let error = max_error_in_counts(&m, &back);
        prop_assert!(error.is_some(), "{:?} came back as {:?}", m, back);
        // Half a count from rounding, plus f32 error of the division by the scale.
        prop_assert!(error.unwrap_or(f32::MAX) <= 0.5 + 1e-2, "{:?} -> {:?}: {:?}", m, back, error);
        // Decoding is stable: encoding the decoded message gives the same bytes.
        prop_assert_eq!(back.encode().expect("re-encodes"), frame);
    }

    #[test]
    fn decoding_any_frame_never_panics(id in 0u16..0x800, data in prop::collection::vec(any::<u8>(), 0..=8)) {
        match Message::decode(id, &data) {
            Ok(m) => prop_assert_eq!(data.len(), 8, "{:?}", m),
            Err(ProtocolError::BadLength { len, .. }) => prop_assert_eq!(len, data.len()),
            Err(ProtocolError::UnknownId(bad)) => prop_assert_eq!(bad, id),
            Err(e) => prop_assert!(false, "unexpected error {}", e),
        }
    }
}

mod fd_option {
    use proptest::prelude::*;
    use vge_bridge::protocol::fd::*;
    use vge_bridge::protocol::*;

    fn node_state() -> impl Strategy<Value = FingerState> {
        (
            (0..FD_NODES as u8, super::triple(3.2), super::triple(30.0), super::triple(3.2)),
            (super::triple(0.5), 0.0f32..60.0, super::triple(1.0)),
            (any::<bool>(), any::<bool>(), any::<bool>(), any::<u8>()),
        )
            .prop_map(|((f, q, dq, tau), (p, force, n), (enabled, fault, in_contact, seq))| {
                FingerState {
                    finger: FingerId::new(f).expect("in range"),
                    q_rad: q,
                    dq_radps: dq,
                    tau_nm: tau,
                    tip_position_m: p,
                    tip_force_n: force,
                    tip_normal: n,
                    enabled,
                    fault,
                    in_contact,
                    seq,
                }
            })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]

        #[test]
        fn node_states_round_trip_and_equal_their_classic_messages(s in node_state()) {
            let frame = FdMessage::NodeState(s).encode().expect("in range");
            let back = FdMessage::decode(frame.id, frame.payload()).expect("own frames decode");
            prop_assert_eq!(back.encode().expect("re-encodes"), frame);
            // Packing the classic messages of the decoded state gives the same FD frame.
            let mut packer = FdPacker::default();
            let mut repacked = None;
            for m in back.to_classic() {
                repacked = packer.push(&m);
            }
            prop_assert_eq!(repacked.map(|r| r.encode().expect("re-encodes")), Some(frame));
        }

        #[test]
        fn fd_decoding_never_panics(id in 0u16..0x800, data in prop::collection::vec(any::<u8>(), 0..=64)) {
            let _ = FdMessage::decode(id, &data);
        }
    }
}
