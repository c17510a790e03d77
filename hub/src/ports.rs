//! The session's services and the serving side of each, as the hub holds them: what `hub::run`
//! and a served replay (`hub::serve`) both open, so the two serve observers and agents alike.

use std::mem::MaybeUninit;

use ipc_services::iceoryx2::node::Node;
use ipc_services::iceoryx2::port::listener::Listener;
use ipc_services::iceoryx2::port::notifier::Notifier;
use ipc_services::iceoryx2::port::publisher::Publisher;
use ipc_services::iceoryx2::port::server::Server;
use ipc_services::iceoryx2::port::subscriber::Subscriber;
use ipc_services::iceoryx2::port::update_connections::UpdateConnections as _;
use ipc_services::iceoryx2::prelude::FileDescriptorBased;
use ipc_services::iceoryx2::prelude::ZeroCopySend;
use ipc_services::iceoryx2::sample_mut::SampleMut;
use ipc_services::iceoryx2::sample_mut_uninit::SampleMutUninit;
use ipc_services::{Role, SLICE_ALLOCATION, Session, Svc};
use ipc_types::{
    ActionBlock, ActionHeader, ChairState, ControlRequest, ControlResponse, MapHeader, MapItem, RegisterRequest,
    RegisterResponse, RobotInfo, RobotState, SensorBlock, TickHeader, WorldHeader,
};

use crate::{HubError, ipc};

/// The publisher of every robot's sensor geometry and the robot ids it last published for.
pub(crate) struct Roster {
    pub(crate) publisher: Publisher<Svc, [RobotInfo], ()>,
    /// The robot ids of the last snapshot, in its order.
    ids: Vec<u32>,
    /// Whether the ids changed since the geometry was last published (true at first).
    changed: bool,
    /// The geometry last published, in the robots' order.
    pub(crate) scratch: Vec<RobotInfo>,
}

impl Roster {
    fn new(publisher: Publisher<Svc, [RobotInfo], ()>) -> Self {
        Self { publisher, ids: Vec::new(), changed: true, scratch: Vec::new() }
    }

    /// Notes the robot ids of the snapshot being published (read from the loaned sample, so
    /// nothing is copied unless the set changed).
    pub(crate) fn note(&mut self, ids: impl Iterator<Item = u32> + Clone) {
        if !self.ids.iter().copied().eq(ids.clone()) {
            self.ids.clear();
            self.ids.extend(ids);
            self.changed = true;
        }
    }

    /// Republishes every robot's sensor geometry when the set of robots noted has changed
    /// since the last time (a robot's sensors are fixed at registration, so ids are enough).
    pub(crate) fn publish_if_changed<I: Iterator<Item = RobotInfo>>(
        &mut self,
        sensors: impl FnOnce() -> I,
    ) -> Result<(), HubError> {
        if !self.changed {
            return Ok(());
        }
        self.changed = false;
        // Kept (not written in place): the recorder takes the geometry with each world frame.
        self.scratch.clear();
        self.scratch.extend(sensors());
        let sample = self.publisher.loan_slice_uninit(self.scratch.len()).map_err(ipc("loan robot sensors"))?;
        sample.write_from_slice(&self.scratch).send().map_err(ipc("send robot sensors"))?;
        Ok(())
    }
}

/// Writes `items` into a loaned slice, element by element, straight into shared memory: how
/// the hub fills every per-tick sample (no scratch `Vec`, no second copy). The loan is sized
/// from the same source, so `items` has exactly as many; were it short, the rest is zeroed
/// rather than left uninitialised.
pub(crate) fn fill<T, H>(
    sample: SampleMutUninit<Svc, [MaybeUninit<T>], H>,
    items: impl IntoIterator<Item = T>,
) -> SampleMut<Svc, [T], H>
where
    T: Copy + std::fmt::Debug + ZeroCopySend + bytemuck::Zeroable,
    H: ZeroCopySend,
{
    let mut items = items.into_iter();
    let sample = sample.write_from_fn(|_| items.next().unwrap_or_else(T::zeroed));
    debug_assert!(items.next().is_none(), "a loan sized from the same source holds every item");
    sample
}

/// Every service of a session and its serving port. Fields drop in order: the ports first,
/// then their services.
pub(crate) struct HubPorts {
    pub(crate) world_pub: Publisher<Svc, [RobotState], WorldHeader>,
    pub(crate) map_pub: Publisher<Svc, [MapItem], MapHeader>,
    pub(crate) observer_map_pub: Publisher<Svc, [MapItem], MapHeader>,
    pub(crate) roster: Roster,
    /// Physical chairs for observers (only sent while the run has chairs).
    pub(crate) chairs_pub: Publisher<Svc, [ChairState], u64>,
    pub(crate) actions_sub: Subscriber<Svc, [ActionBlock], ActionHeader>,
    pub(crate) register_server: Server<Svc, RegisterRequest, (), RegisterResponse, ()>,
    pub(crate) control_server: Server<Svc, ControlRequest, (), ControlResponse, ()>,
    pub(crate) tick_notifier: Notifier<Svc>,
    pub(crate) doorbell: Listener<Svc>,
    pub(crate) world_svc: ipc_services::WorldService,
    _map_svc: ipc_services::MapService,
    _observer_map_svc: ipc_services::MapService,
    _sensors_svc: ipc_services::RobotInfoService,
    _chairs_svc: ipc_services::ChairService,
    _actions_svc: ipc_services::ActionService,
    _register_svc: ipc_services::RegisterService,
    _control_svc: ipc_services::ControlService,
    _tick_svc: ipc_services::EventService,
    _doorbell_svc: ipc_services::EventService,
}

impl HubPorts {
    /// Creates the session's services (failing if another process serves it) and their ports,
    /// and publishes the two maps, kept for late subscribers: the agents' (no scenario
    /// obstacles: their sensors must find those) and the observers' (the truth).
    pub(crate) fn open(
        session: &Session,
        node: &Node<Svc>,
        agents_map: (MapHeader, Vec<MapItem>),
        observers_map: (MapHeader, Vec<MapItem>),
    ) -> Result<Self, HubError> {
        let world_svc = session.world(node, Role::Hub)?;
        let map_svc = session.map(node, Role::Hub)?;
        let observer_map_svc = session.observer_map(node, Role::Hub)?;
        let sensors_svc = session.robot_info(node, Role::Hub)?;
        let actions_svc = session.actions(node, Role::Hub)?;
        let chairs_svc = session.observer_chairs(node, Role::Hub)?;
        let register_svc = session.register(node, Role::Hub)?;
        let control_svc = session.control(node, Role::Hub)?;
        let tick_svc = session.tick_event(node, Role::Hub)?;
        let doorbell_svc = session.hub_event(node, Role::Hub)?;
        let world_pub = world_svc
            .publisher_builder()
            .initial_max_slice_len(64)
            .allocation_strategy(SLICE_ALLOCATION)
            .create()
            .map_err(ipc("create the world publisher"))?;
        let sensors_pub = sensors_svc
            .publisher_builder()
            .initial_max_slice_len(64)
            .allocation_strategy(SLICE_ALLOCATION)
            .create()
            .map_err(ipc("create the robot-info publisher"))?;
        let chairs_pub = chairs_svc
            .publisher_builder()
            .initial_max_slice_len(4)
            .allocation_strategy(SLICE_ALLOCATION)
            .create()
            .map_err(ipc("create the chairs publisher"))?;
        let publish_map = |svc: &ipc_services::MapService, (header, items): (MapHeader, Vec<MapItem>)| {
            let publisher = svc
                .publisher_builder()
                .initial_max_slice_len(items.len().max(1))
                .allocation_strategy(SLICE_ALLOCATION)
                .create()
                .map_err(ipc("create a map publisher"))?;
            let mut sample = publisher.loan_slice_uninit(items.len()).map_err(ipc("loan the map"))?;
            *sample.user_header_mut() = header;
            sample.write_from_slice(&items).send().map_err(ipc("send the map"))?;
            Ok::<_, HubError>(publisher)
        };
        let map_pub = publish_map(&map_svc, agents_map)?;
        let observer_map_pub = publish_map(&observer_map_svc, observers_map)?;
        Ok(Self {
            world_pub,
            map_pub,
            observer_map_pub,
            roster: Roster::new(sensors_pub),
            chairs_pub,
            actions_sub: actions_svc.subscriber_builder().create().map_err(ipc("create the actions subscriber"))?,
            register_server: register_svc.server_builder().create().map_err(ipc("create the register server"))?,
            control_server: control_svc.server_builder().create().map_err(ipc("create the control server"))?,
            tick_notifier: tick_svc.notifier_builder().create().map_err(ipc("create the tick notifier"))?,
            doorbell: doorbell_svc.listener_builder().create().map_err(ipc("create the doorbell listener"))?,
            world_svc,
            _map_svc: map_svc,
            _observer_map_svc: observer_map_svc,
            _sensors_svc: sensors_svc,
            _chairs_svc: chairs_svc,
            _actions_svc: actions_svc,
            _register_svc: register_svc,
            _control_svc: control_svc,
            _tick_svc: tick_svc,
            _doorbell_svc: doorbell_svc,
        })
    }

    /// The doorbell listener's file descriptor, for `poll(2)`.
    pub(crate) fn doorbell_fd(&self) -> i32 {
        #[allow(unsafe_code)]
        // SAFETY: the listener lives as long as `self`; only the fd number is read.
        unsafe {
            self.doorbell.file_descriptor().native_handle()
        }
    }

    /// Lets the publishers meet subscribers that came since the last call.
    pub(crate) fn update_connections(&self) {
        let _ = self.map_pub.update_connections();
        let _ = self.observer_map_pub.update_connections();
        let _ = self.world_pub.update_connections();
        let _ = self.roster.publisher.update_connections();
        let _ = self.chairs_pub.update_connections();
    }
}

/// Publishes the chairs' states for observers, when the run has chairs: `count` of them,
/// written in place.
pub(crate) fn publish_chairs(
    publisher: &Publisher<Svc, [ChairState], u64>,
    tick: u64,
    count: usize,
    states: impl Iterator<Item = ChairState>,
) -> Result<(), HubError> {
    if count == 0 {
        return Ok(());
    }
    let mut sample = publisher.loan_slice_uninit(count).map_err(ipc("loan chair states"))?;
    *sample.user_header_mut() = tick;
    fill(sample, states).send().map_err(ipc("send chair states"))?;
    Ok(())
}

/// The publisher of an agent's sensor blocks.
pub(crate) type SensorPublisher = Publisher<Svc, [SensorBlock], TickHeader>;

/// An agent's sensor-block service and its publisher, made at its hello.
pub(crate) fn agent_sensor_port(
    session: &Session,
    node: &Node<Svc>,
    agent_id: u32,
) -> Result<(ipc_services::SensorService, SensorPublisher), String> {
    let service = session.agent_sensors(node, agent_id, Role::Hub).map_err(|e| e.to_string())?;
    let publisher = service
        .publisher_builder()
        .initial_max_slice_len(4)
        .allocation_strategy(SLICE_ALLOCATION)
        .create()
        .map_err(|e| format!("{e:?}"))?;
    Ok((service, publisher))
}
