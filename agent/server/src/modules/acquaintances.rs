//! The vision module's acquaintances (`Agent.acquaintances`, docs/vision.md "Acquaintance"): the faces the agent
//! was introduced to, kept in the pair database under `agent.faces.<name>` and handed to the per-face analysis so
//! that it names them. Nothing is stored until a rule asks (`learn_face`); `forget_face` erases the entry.

use agent_contract::acquaintance::{
    self, AcquaintanceAnswer, AcquaintanceRecord, AcquaintanceRequest, KEY_PREFIX,
};
use agent_face::{Acquaintance, Descriptor, recognise};
use bytes::Bytes;
use flow::Client;
use tracing::{info, warn};

use super::vision_worker::PeopleLink;

/// The people the agent knows, as the pair database has them.
#[derive(Debug)]
pub struct Acquaintances {
    known: Vec<Acquaintance>,
    match_distance: f32,
}

impl Acquaintances {
    /// Reads every entry under [`KEY_PREFIX`]; an entry that does not read is skipped with a warning.
    pub async fn load(client: &Client, match_distance: f32) -> Acquaintances {
        let mut known = Vec::new();
        let keys = match client.var_list().await {
            Ok(keys) => keys,
            Err(e) => {
                warn!("vision: cannot list the pair database ({e}); no acquaintances");
                Vec::new()
            }
        };
        for key in keys.iter().filter(|k| k.starts_with(KEY_PREFIX)) {
            let record = match client.var_get(key).await {
                Ok(Some(value)) => serde_json::from_value::<AcquaintanceRecord>(value),
                Ok(None) => continue,
                Err(e) => {
                    warn!(key, "vision: cannot read an acquaintance: {e}");
                    continue;
                }
            };
            match record
                .ok()
                .and_then(|r| Descriptor::from_slice(&r.descriptor).map(|d| (r.name, d)))
            {
                Some((name, descriptor)) => known.push(Acquaintance { name, descriptor }),
                None => warn!(
                    key,
                    "vision: an acquaintance's entry does not read; skipped"
                ),
            }
        }
        if !known.is_empty() {
            info!(count = known.len(), "vision: acquaintances loaded");
        }
        Acquaintances {
            known,
            match_distance,
        }
    }

    pub fn known(&self) -> &[Acquaintance] {
        &self.known
    }

    /// Answers one request, storing or erasing in the pair database and telling the analysis.
    pub async fn handle(
        &mut self,
        client: &Client,
        link: &PeopleLink,
        payload: &[u8],
    ) -> Result<Bytes, String> {
        let request: AcquaintanceRequest =
            serde_json::from_slice(payload).map_err(|e| format!("bad request: {e}"))?;
        let (person, descriptor) = link.learnable().ok_or_else(|| {
            "no face to go by: nobody in view has been talking, and there is not just one face turned to the camera"
                .to_owned()
        })?;
        let answer = match request {
            AcquaintanceRequest::Learn(name) => {
                let name = acquaintance::clean_name(&name)?;
                let record = AcquaintanceRecord {
                    name: name.clone(),
                    descriptor: descriptor.to_vec(),
                    learned_ms: unix_ms(),
                };
                let value = serde_json::to_value(&record).map_err(|e| e.to_string())?;
                client
                    .var_set(&acquaintance::key(&name), &value)
                    .await
                    .map_err(|e| format!("the pair database did not store it: {e}"))?;
                // One entry per name, and one name per face: a face introduced again under another name drops
                // its old entry.
                let same_face: Vec<String> = self
                    .known
                    .iter()
                    .filter(|p| {
                        p.name != name && p.descriptor.distance(&descriptor) < self.match_distance
                    })
                    .map(|p| p.name.clone())
                    .collect();
                for old in &same_face {
                    self.erase(client, old).await?;
                }
                self.known.retain(|p| p.name != name);
                self.known.push(Acquaintance {
                    name: name.clone(),
                    descriptor,
                });
                info!(person, name, "vision: learned a face");
                AcquaintanceAnswer {
                    name,
                    person,
                    done: "learned".into(),
                }
            }
            AcquaintanceRequest::Forget(_) => {
                let name = recognise(&descriptor, &self.known, self.match_distance)
                    .map(|(p, _)| p.name.clone())
                    .ok_or_else(|| "this face is not one the agent knows".to_owned())?;
                self.erase(client, &name).await?;
                info!(person, name, "vision: forgot a face");
                AcquaintanceAnswer {
                    name,
                    person,
                    done: "forgotten".into(),
                }
            }
        };
        link.set_known(self.known.clone());
        serde_json::to_vec(&answer)
            .map(Bytes::from)
            .map_err(|e| e.to_string())
    }

    async fn erase(&mut self, client: &Client, name: &str) -> Result<(), String> {
        client
            .var_del(&acquaintance::key(name))
            .await
            .map_err(|e| format!("the pair database did not erase it: {e}"))?;
        self.known.retain(|p| p.name != name);
        Ok(())
    }
}

fn unix_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64)
}
