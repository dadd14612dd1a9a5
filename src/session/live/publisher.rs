//! The publisher thread of the live view: takes the session's records off the queue, decimates
//! the DAQ blocks, serialises to JSON and logs to the server's channels. A channel no client
//! subscribed to costs nothing but the decimation.

use std::sync::mpsc::Receiver;
use std::sync::{Arc, Mutex, PoisonError};

use foxglove::websocket::{ChannelView, Client, ServerListener};
use foxglove::{Context, FoxgloveError, PartialMetadata, RawChannel, Schema};
use serde::ser::{SerializeMap, Serializer};
use serde::Serialize;

use crate::control::{ControlState, SessionEvent};
use crate::log::{log_time_ns, MESSAGE_ENCODING, SCHEMA_ENCODING};
use crate::rig::DaqLayout;
use crate::twin::{TwinBlock, TwinStatus};

use super::super::topics::{
    StatusMessage, StepMessage, TwinStepMessage, TOPIC_CONTROL, TOPIC_EVENTS, TOPIC_LAYOUT,
    TOPIC_LIVE_DAQ, TOPIC_LIVE_TWIN, TOPIC_STATUS, TOPIC_STEPS, TOPIC_TWIN_STATUS,
    TOPIC_TWIN_STEPS,
};
use super::decimate::{bin_samples, DecimatedPoint, MinMaxDecimator};
use super::record::{LiveStats, Record};
use super::{LiveOptions, LIVE_DAQ_SCHEMA, LIVE_TWIN_CHANNELS, LIVE_TWIN_SCHEMA};

/// Keys of a live DAQ point besides the channels; a channel with one of these names is published
/// as `ch_NAME`.
const POINT_KEYS: [&str; 3] = ["time", "first_sample", "samples"];

/// The channels that exist from the start (the DAQ points wait for the layout).
pub(super) struct Channels {
    pub(super) layout: Arc<RawChannel>,
    control: Arc<RawChannel>,
    events: Arc<RawChannel>,
    status: Arc<RawChannel>,
    steps: Arc<RawChannel>,
}

/// A JSON channel with `T`'s JSON Schema, named as in the MCAP session log.
fn json_channel<T: schemars::JsonSchema>(
    ctx: &Arc<Context>,
    topic: &str,
) -> Result<Arc<RawChannel>, FoxgloveError> {
    let schema = json_schema::<T>().map_err(|e| FoxgloveError::ValueError(e.to_string()))?;
    raw_channel(ctx, topic, &T::schema_name(), schema)
}

fn json_schema<T: schemars::JsonSchema>() -> Result<Vec<u8>, serde_json::Error> {
    serde_json::to_vec(&schemars::schema_for!(T))
}

/// A topic the live view serves and its JSON Schema.
#[derive(Clone, Debug, PartialEq)]
pub struct TopicSchema {
    /// Topic name.
    pub topic: &'static str,
    /// Schema name (as advertised).
    pub schema_name: String,
    /// The JSON Schema, as advertised.
    pub schema: Vec<u8>,
}

/// Every topic the live view serves for a session with the DAQ `layout` (with the live twin),
/// with the schema it advertises: what a Foxglove layout may refer to.
pub fn topic_schemas(layout: &DaqLayout, options: &LiveOptions) -> Vec<TopicSchema> {
    fn of<T: schemars::JsonSchema>(topic: &'static str) -> TopicSchema {
        TopicSchema {
            topic,
            schema_name: T::schema_name().to_string(),
            schema: json_schema::<T>().unwrap_or_default(),
        }
    }
    let bin = bin_samples(layout.sample_rate, options.daq_points_per_second);
    vec![
        of::<DaqLayout>(TOPIC_LAYOUT),
        of::<ControlState>(TOPIC_CONTROL),
        of::<SessionEvent>(TOPIC_EVENTS),
        of::<StatusMessage>(TOPIC_STATUS),
        of::<StepMessage>(TOPIC_STEPS),
        of::<TwinStatus>(TOPIC_TWIN_STATUS),
        of::<TwinStepMessage>(TOPIC_TWIN_STEPS),
        TopicSchema {
            topic: TOPIC_LIVE_DAQ,
            schema_name: LIVE_DAQ_SCHEMA.to_string(),
            schema: daq_point_schema(layout, &daq_keys(layout), bin),
        },
        TopicSchema {
            topic: TOPIC_LIVE_TWIN,
            schema_name: LIVE_TWIN_SCHEMA.to_string(),
            schema: twin_point_schema(layout.sample_rate, bin),
        },
    ]
}

/// The keys of `/live/daq`'s channels: the channel names, `ch_NAME` for one that clashes with
/// [`POINT_KEYS`].
fn daq_keys(layout: &DaqLayout) -> Vec<String> {
    layout
        .channels
        .iter()
        .map(|c| {
            if POINT_KEYS.contains(&c.name.as_str()) {
                format!("ch_{}", c.name)
            } else {
                c.name.clone()
            }
        })
        .collect()
}

fn raw_channel(
    ctx: &Arc<Context>,
    topic: &str,
    schema_name: &str,
    schema: Vec<u8>,
) -> Result<Arc<RawChannel>, FoxgloveError> {
    ctx.channel_builder(topic)
        .message_encoding(MESSAGE_ENCODING)
        .schema(Schema::new(schema_name, SCHEMA_ENCODING, schema))
        .build_raw()
}

impl Channels {
    pub(super) fn new(ctx: &Arc<Context>) -> Result<Self, FoxgloveError> {
        Ok(Self {
            layout: json_channel::<DaqLayout>(ctx, TOPIC_LAYOUT)?,
            control: json_channel::<ControlState>(ctx, TOPIC_CONTROL)?,
            events: json_channel::<SessionEvent>(ctx, TOPIC_EVENTS)?,
            status: json_channel::<StatusMessage>(ctx, TOPIC_STATUS)?,
            steps: json_channel::<StepMessage>(ctx, TOPIC_STEPS)?,
        })
    }
}

/// Sends the layout (logged once at the start) to every client that subscribes to it later.
pub(super) struct LayoutLatch {
    channel: Arc<RawChannel>,
    json: Mutex<Option<Arc<[u8]>>>,
}

impl LayoutLatch {
    pub(super) fn new(channel: Arc<RawChannel>) -> Self {
        Self {
            channel,
            json: Mutex::new(None),
        }
    }

    fn set(&self, json: &[u8]) {
        *self.json.lock().unwrap_or_else(PoisonError::into_inner) = Some(json.into());
    }
}

impl ServerListener for LayoutLatch {
    fn on_subscribe(&self, client: Client, channel: ChannelView) {
        if channel.id() != self.channel.id() {
            return;
        }
        let json = self
            .json
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone();
        if let Some(json) = json {
            self.channel.log_with_meta_to_sink(
                &json,
                PartialMetadata::with_log_time(log_time_ns(0.0)),
                client.sink_id(),
            );
        }
    }
}

/// A decimated topic (`/live/daq`, made when the layout arrives; `/live/twin`, made with the
/// twin's first block).
struct PointTopic {
    channel: Arc<RawChannel>,
    /// Key per channel in the messages.
    keys: Vec<String>,
    decimator: MinMaxDecimator,
}

impl PointTopic {
    fn finish(&mut self, buf: &mut Vec<u8>, stats: &mut LiveStats) {
        let (channel, keys) = (&self.channel, &self.keys);
        self.decimator.finish(&mut |p| {
            publish_point(channel, keys, p, buf, stats);
        });
    }
}

/// The live twin's topics (made with its first record).
struct TwinTopics {
    status: Arc<RawChannel>,
    steps: Arc<RawChannel>,
    /// `/live/twin`, made with the first twin block after the layout (which gives the rate).
    points: Option<PointTopic>,
    /// Reused buffer of a twin block's decimated channels, channel-major.
    values: Vec<f64>,
}

/// The publisher thread's state.
pub(super) struct Publisher {
    ctx: Arc<Context>,
    channels: Channels,
    latch: Arc<LayoutLatch>,
    points_per_second: f64,
    daq: Option<PointTopic>,
    /// The DAQ's sample rate, Hz (from the layout).
    sample_rate: Option<f64>,
    twin: Option<TwinTopics>,
    /// Reused serialisation buffer.
    buf: Vec<u8>,
    stats: LiveStats,
}

impl Publisher {
    pub(super) fn new(
        ctx: Arc<Context>,
        channels: Channels,
        latch: Arc<LayoutLatch>,
        points_per_second: f64,
    ) -> Self {
        Self {
            ctx,
            channels,
            latch,
            points_per_second,
            daq: None,
            sample_rate: None,
            twin: None,
            buf: Vec::with_capacity(4096),
            stats: LiveStats::default(),
        }
    }

    /// Publishes records until [`Record::Close`] or until the recorder and the view are gone.
    pub(super) fn run(mut self, rx: Receiver<Record>) -> LiveStats {
        while let Ok(record) = rx.recv() {
            match record {
                Record::Close => break,
                r => self.apply(r),
            }
        }
        if let Some(d) = &mut self.daq {
            d.finish(&mut self.buf, &mut self.stats);
        }
        if let Some(t) = self.twin.as_mut().and_then(|t| t.points.as_mut()) {
            t.finish(&mut self.buf, &mut self.stats);
        }
        self.stats.skipped_blocks = self
            .daq
            .as_ref()
            .map_or(0, |d| d.decimator.skipped_blocks());
        self.stats
    }

    fn apply(&mut self, record: Record) {
        match record {
            Record::Layout(layout) => {
                self.serialise(&layout);
                self.latch.set(&self.buf);
                let ch = Arc::clone(&self.channels.layout);
                self.send(&ch, 0.0);
                self.sample_rate = Some(layout.sample_rate);
                self.daq = self.daq_topic(&layout);
            }
            Record::Block(block) => {
                if let Some(d) = &mut self.daq {
                    let (buf, stats) = (&mut self.buf, &mut self.stats);
                    d.decimator.push(&block, &mut |p| {
                        publish_point(&d.channel, &d.keys, p, buf, stats);
                    });
                }
            }
            Record::Control(c) => self.publish(TopicOf::Control, c.time, &c),
            Record::Event(e) => self.publish(TopicOf::Events, e.time, &e),
            Record::Status(s) => self.publish(TopicOf::Status, s.block_time, &s),
            Record::Step(time, s) => self.publish(TopicOf::Steps, time, &s),
            Record::TwinBlock(b) => self.twin_block(&b),
            Record::TwinStatus(time, s) => self.publish(TopicOf::TwinStatus, time, &s),
            Record::TwinStep(time, s) => self.publish(TopicOf::TwinSteps, time, &s),
            Record::Close => {}
        }
    }

    /// The twin's topics, made on first use.
    fn twin_topics(&mut self) -> Option<&mut TwinTopics> {
        if self.twin.is_none() {
            let made =
                json_channel::<TwinStatus>(&self.ctx, TOPIC_TWIN_STATUS).and_then(|status| {
                    Ok(TwinTopics {
                        status,
                        steps: json_channel::<TwinStepMessage>(&self.ctx, TOPIC_TWIN_STEPS)?,
                        points: None,
                        values: Vec::new(),
                    })
                });
            match made {
                Ok(t) => self.twin = Some(t),
                Err(e) => tracing::warn!("live view: cannot create the twin's topics: {e}"),
            }
        }
        self.twin.as_mut()
    }

    /// Decimates a twin block onto `/live/twin` (bins aligned with `/live/daq`'s).
    fn twin_block(&mut self, b: &TwinBlock) {
        let (Some(rate), pps) = (self.sample_rate, self.points_per_second) else {
            return; // no layout yet: nothing to put the twin beside
        };
        let ctx = Arc::clone(&self.ctx);
        self.twin_topics();
        let Some(t) = self.twin.as_mut() else {
            return;
        };
        if t.points.is_none() {
            let bin = bin_samples(rate, pps);
            let keys: Vec<String> = LIVE_TWIN_CHANNELS.iter().map(|c| c.0.to_string()).collect();
            match raw_channel(
                &ctx,
                TOPIC_LIVE_TWIN,
                LIVE_TWIN_SCHEMA,
                twin_point_schema(rate, bin),
            ) {
                Ok(channel) => {
                    t.points = Some(PointTopic {
                        channel,
                        decimator: MinMaxDecimator::with_scales(rate, vec![1.0; keys.len()], bin),
                        keys,
                    })
                }
                Err(e) => {
                    tracing::warn!("live view: cannot create {TOPIC_LIVE_TWIN}: {e}");
                    return;
                }
            }
        }
        let Some(points) = t.points.as_mut() else {
            return;
        };
        // LIVE_TWIN_CHANNELS order: the four sensors, contact, normal and tangential force.
        t.values.clear();
        t.values.extend_from_slice(&b.velocity);
        t.values
            .extend(b.contact.iter().map(|&c| if c { 1.0 } else { 0.0 }));
        t.values.extend_from_slice(&b.normal_force);
        t.values.extend_from_slice(&b.tangential_force);
        let (buf, stats) = (&mut self.buf, &mut self.stats);
        let (channel, keys) = (&points.channel, &points.keys);
        points
            .decimator
            .push_values(b.first_sample, b.len, &t.values, &mut |p| {
                publish_point(channel, keys, p, buf, stats);
            });
    }

    fn channel(&mut self, which: TopicOf) -> Option<&Arc<RawChannel>> {
        Some(match which {
            TopicOf::Control => &self.channels.control,
            TopicOf::Events => &self.channels.events,
            TopicOf::Status => &self.channels.status,
            TopicOf::Steps => &self.channels.steps,
            TopicOf::TwinStatus => &self.twin_topics()?.status,
            TopicOf::TwinSteps => &self.twin_topics()?.steps,
        })
    }

    /// Serialises and sends `value` if some client subscribed to the topic.
    fn publish<T: Serialize>(&mut self, which: TopicOf, time: f64, value: &T) {
        let Some(ch) = self.channel(which).map(Arc::clone) else {
            return;
        };
        if !ch.has_sinks() {
            return;
        }
        self.serialise(value);
        self.send(&ch, time);
    }

    fn serialise<T: Serialize>(&mut self, value: &T) {
        self.buf.clear();
        if let Err(e) = serde_json::to_writer(&mut self.buf, value) {
            // Not reachable for the session's types (no maps with non-string keys).
            tracing::warn!("live view: cannot serialise a message: {e}");
            self.buf.clear();
        }
    }

    fn send(&mut self, ch: &RawChannel, time: f64) {
        if self.buf.is_empty() || !ch.has_sinks() {
            return;
        }
        ch.log_with_meta(&self.buf, PartialMetadata::with_log_time(log_time_ns(time)));
        *self.stats.sent.entry(ch.topic().to_string()).or_insert(0) += 1;
    }

    fn daq_topic(&self, layout: &DaqLayout) -> Option<PointTopic> {
        let keys = daq_keys(layout);
        let bin = bin_samples(layout.sample_rate, self.points_per_second);
        let schema = daq_point_schema(layout, &keys, bin);
        match raw_channel(&self.ctx, TOPIC_LIVE_DAQ, LIVE_DAQ_SCHEMA, schema) {
            Ok(channel) => Some(PointTopic {
                channel,
                keys,
                decimator: MinMaxDecimator::new(layout, bin),
            }),
            Err(e) => {
                tracing::warn!("live view: cannot create {TOPIC_LIVE_DAQ}: {e}");
                None
            }
        }
    }
}

#[derive(Clone, Copy)]
enum TopicOf {
    Control,
    Events,
    Status,
    Steps,
    TwinStatus,
    TwinSteps,
}

/// Serialises a decimated point into `buf` and sends it if a client subscribed.
fn publish_point(
    channel: &RawChannel,
    keys: &[String],
    point: &DecimatedPoint<'_>,
    buf: &mut Vec<u8>,
    stats: &mut LiveStats,
) {
    stats.points += 1;
    if !channel.has_sinks() {
        return;
    }
    buf.clear();
    if serde_json::to_writer(&mut *buf, &PointJson { keys, point }).is_err() {
        return;
    }
    channel.log_with_meta(buf, PartialMetadata::with_log_time(log_time_ns(point.time)));
    *stats.sent.entry(channel.topic().to_string()).or_insert(0) += 1;
}

/// A decimated point as JSON: `{"time", "first_sample", "samples", CHANNEL: {"min", "max",
/// "mean"}, ...}`.
struct PointJson<'a> {
    keys: &'a [String],
    point: &'a DecimatedPoint<'a>,
}

#[derive(Serialize)]
struct Stats {
    min: f64,
    max: f64,
    mean: f64,
}

impl Serialize for PointJson<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let p = self.point;
        let mut m = s.serialize_map(Some(3 + self.keys.len()))?;
        m.serialize_entry("time", &p.time)?;
        m.serialize_entry("first_sample", &p.first_sample)?;
        m.serialize_entry("samples", &p.samples)?;
        for (k, key) in self.keys.iter().enumerate() {
            m.serialize_entry(
                key,
                &Stats {
                    min: p.min[k],
                    max: p.max[k],
                    mean: p.mean[k],
                },
            )?;
        }
        m.end()
    }
}

/// One channel of a decimated topic's schema: its key, what it is, its unit.
struct PointChannel {
    key: String,
    what: String,
    unit: &'static str,
}

/// The JSON Schema of a decimated point of `layout`: every channel a property, so the Foxglove
/// app completes `/live/daq.upper_tip.max`.
fn daq_point_schema(layout: &DaqLayout, keys: &[String], bin: usize) -> Vec<u8> {
    let channels: Vec<PointChannel> = layout
        .channels
        .iter()
        .zip(keys)
        .map(|(c, key)| {
            let kind = serde_json::to_value(c.kind)
                .ok()
                .and_then(|v| v.as_str().map(str::to_string))
                .unwrap_or_default();
            PointChannel {
                key: key.clone(),
                what: format!("DAQ channel {} ({kind})", c.name),
                unit: c.kind.unit(),
            }
        })
        .collect();
    point_schema(
        LIVE_DAQ_SCHEMA,
        &format!(
            "DAQ samples decimated for plotting: bins of {bin} samples at {} Hz, every \
             channel's min, max and mean in physical units",
            layout.sample_rate
        ),
        &channels,
        bin,
    )
}

/// The JSON Schema of a decimated point of the twin's prediction ([`LIVE_TWIN_CHANNELS`]).
fn twin_point_schema(sample_rate: f64, bin: usize) -> Vec<u8> {
    let channels: Vec<PointChannel> = LIVE_TWIN_CHANNELS
        .iter()
        .map(|&(key, what, unit)| PointChannel {
            key: key.to_string(),
            what: format!("twin: {what}"),
            unit,
        })
        .collect();
    point_schema(
        LIVE_TWIN_SCHEMA,
        &format!(
            "The live twin's prediction decimated for plotting, in the same bins as {}: bins \
             of {bin} samples at {sample_rate} Hz, every channel's min, max and mean",
            TOPIC_LIVE_DAQ
        ),
        &channels,
        bin,
    )
}

fn point_schema(title: &str, description: &str, channels: &[PointChannel], bin: usize) -> Vec<u8> {
    let number = |d: &str| serde_json::json!({"type": "number", "description": d});
    let mut properties = serde_json::Map::new();
    properties.insert(
        "time".into(),
        number("Rig time of the bin's first sample, s (also the message's log time)"),
    );
    properties.insert(
        "first_sample".into(),
        serde_json::json!({"type": "integer", "minimum": 0,
            "description": "Index of the bin's first DAQ sample since the stream started"}),
    );
    properties.insert(
        "samples".into(),
        serde_json::json!({"type": "integer", "minimum": 1, "description": format!(
            "Samples in the bin: {bin}, fewer when a gap in the stream or the end of the \
             session cut the bin short")}),
    );
    for c in channels {
        let unit = c.unit;
        properties.insert(
            c.key.clone(),
            serde_json::json!({
                "type": "object",
                "description": format!("{} over the bin, {unit}", c.what),
                "properties": {
                    "min": number(&format!("Smallest sample, {unit}")),
                    "max": number(&format!("Largest sample, {unit}")),
                    "mean": number(&format!(
                        "Mean of the bin's samples (a boxcar average), {unit}")),
                },
                "required": ["min", "max", "mean"],
            }),
        );
    }
    let required: Vec<&str> = POINT_KEYS
        .iter()
        .copied()
        .chain(channels.iter().map(|c| c.key.as_str()))
        .collect();
    let schema = serde_json::json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": title,
        "description": description,
        "type": "object",
        "properties": properties,
        "required": required,
    });
    serde_json::to_vec(&schema).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::{ChannelKind, ChannelSpec};

    #[test]
    fn a_point_serialises_with_every_channel_as_declared_in_its_schema() {
        let layout = DaqLayout {
            sample_rate: 1000.0,
            block_size: 10,
            channels: vec![
                ChannelSpec {
                    name: "upper_tip".into(),
                    kind: ChannelKind::BeamAcceleration,
                    scale: 1e-3,
                    full_scale_counts: 1000,
                },
                ChannelSpec {
                    name: "time".into(),
                    kind: ChannelKind::DriveVoltage,
                    scale: 1e-3,
                    full_scale_counts: 1000,
                },
            ],
        };
        let keys = vec!["upper_tip".to_string(), "ch_time".to_string()];
        let point = DecimatedPoint {
            first_sample: 40,
            time: 0.04,
            samples: 5,
            min: &[-1.0, 0.0],
            max: &[2.0, 0.5],
            mean: &[0.25, 0.1],
        };
        let json: serde_json::Value = serde_json::to_value(PointJson {
            keys: &keys,
            point: &point,
        })
        .unwrap();
        assert_eq!(json["time"], 0.04);
        assert_eq!(json["first_sample"], 40);
        assert_eq!(json["upper_tip"]["max"], 2.0);
        assert_eq!(json["ch_time"]["mean"], 0.1);
        let schema: serde_json::Value =
            serde_json::from_slice(&daq_point_schema(&layout, &keys, 5)).unwrap();
        let props = schema["properties"].as_object().unwrap();
        for key in json.as_object().unwrap().keys() {
            assert!(props.contains_key(key), "{key} not in the schema");
        }
        assert_eq!(schema["required"].as_array().unwrap().len(), 5);
        assert!(schema["properties"]["upper_tip"]["description"]
            .as_str()
            .unwrap()
            .contains("m/s^2"));
    }
}
