//! The passages in a tantivy index in RAM: a heading field and a body field, both analysed by the folder's
//! language, scored with BM25; the query is the question's terms, any of which may match.

use tantivy::collector::TopDocs;
use tantivy::query::{BooleanQuery, BoostQuery, Occur, Query, TermQuery};
use tantivy::schema::{
    Field, IndexRecordOption, STORED, Schema, TextFieldIndexing, TextOptions, Value,
};
use tantivy::tokenizer::TextAnalyzer;
use tantivy::{DocAddress, IndexWriter, ReloadPolicy, Searcher, TantivyDocument, Term};

/// The analyzer's name in the index's tokenizer manager.
const ANALYZER: &str = "knowledge";

/// A match in a heading counts this much more than one in the body: a section named after the question's subject
/// is about it, where a passage may mention a word in passing.
const HEADING_BOOST: f32 = 1.5;

/// The indexing memory tantivy's writer gets: its lower bound is 15 MB per thread; the folder is small, so one
/// thread and a little above the bound hold it in one segment.
const WRITER_BYTES: usize = 20_000_000;

/// One passage as indexed.
#[derive(Debug, Clone, Copy)]
pub struct Document<'a> {
    /// The words the heading field gets: the heading path and the file's name.
    pub heading: &'a str,
    pub body: &'a str,
}

/// The built index, read-only.
pub struct Index {
    searcher: Searcher,
    heading: Field,
    body: Field,
    id: Field,
}

impl std::fmt::Debug for Index {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Index")
            .field("documents", &self.searcher.num_docs())
            .finish()
    }
}

impl Index {
    /// Indexes `documents`; a hit's id is its document's position in the slice.
    pub fn build(
        documents: &[Document<'_>],
        analyzer: TextAnalyzer,
    ) -> Result<Index, tantivy::TantivyError> {
        let mut schema = Schema::builder();
        // Frequencies without positions: BM25 needs no more, and there are no phrase queries.
        let text = TextOptions::default().set_indexing_options(
            TextFieldIndexing::default()
                .set_tokenizer(ANALYZER)
                .set_index_option(IndexRecordOption::WithFreqs),
        );
        let heading = schema.add_text_field("heading", text.clone());
        let body = schema.add_text_field("body", text);
        let id = schema.add_u64_field("id", STORED);
        let index = tantivy::Index::create_in_ram(schema.build());
        index.tokenizers().register(ANALYZER, analyzer);
        let mut writer: IndexWriter = index.writer_with_num_threads(1, WRITER_BYTES)?;
        for (n, d) in documents.iter().enumerate() {
            let mut doc = TantivyDocument::default();
            doc.add_text(heading, d.heading);
            doc.add_text(body, d.body);
            doc.add_u64(id, n as u64);
            writer.add_document(doc)?;
        }
        writer.commit()?;
        // The writer's threads end here: an idle index holds no thread.
        writer.wait_merging_threads()?;
        // Nothing is written after this, so the reader never reloads (and runs no watcher for it).
        let reader = index
            .reader_builder()
            .reload_policy(ReloadPolicy::Manual)
            .try_into()?;
        Ok(Index {
            searcher: reader.searcher(),
            heading,
            body,
            id,
        })
    }

    /// The best `limit` documents for `terms` (analysed already), best first, as (BM25 score, id).
    pub fn search(
        &self,
        terms: &[String],
        limit: usize,
    ) -> Result<Vec<(f32, usize)>, tantivy::TantivyError> {
        if terms.is_empty() || limit == 0 {
            return Ok(Vec::new());
        }
        let mut clauses: Vec<(Occur, Box<dyn Query>)> = Vec::with_capacity(terms.len() * 2);
        for term in terms {
            clauses.push((
                Occur::Should,
                Box::new(TermQuery::new(
                    Term::from_field_text(self.body, term),
                    IndexRecordOption::WithFreqs,
                )),
            ));
            clauses.push((
                Occur::Should,
                Box::new(BoostQuery::new(
                    Box::new(TermQuery::new(
                        Term::from_field_text(self.heading, term),
                        IndexRecordOption::WithFreqs,
                    )),
                    HEADING_BOOST,
                )),
            ));
        }
        let query = BooleanQuery::new(clauses);
        let top = self
            .searcher
            .search(&query, &TopDocs::with_limit(limit).order_by_score())?;
        let mut out = Vec::with_capacity(top.len());
        for (score, address) in top {
            out.push((score, self.id_of(address)?));
        }
        Ok(out)
    }

    /// How much a term says (BM25's inverse document frequency over heading or body): a term in every passage
    /// near 0, a term in none the most.
    pub fn idf(&self, term: &str) -> Result<f32, tantivy::TantivyError> {
        let n = self.searcher.num_docs() as f32;
        let in_body = self
            .searcher
            .doc_freq(&Term::from_field_text(self.body, term))?;
        let in_heading = self
            .searcher
            .doc_freq(&Term::from_field_text(self.heading, term))?;
        let df = in_body.max(in_heading) as f32;
        Ok((1.0 + (n - df + 0.5) / (df + 0.5)).ln())
    }

    fn id_of(&self, address: DocAddress) -> Result<usize, tantivy::TantivyError> {
        let doc: TantivyDocument = self.searcher.doc(address)?;
        doc.get_first(self.id)
            .and_then(|v| v.as_u64())
            .map(|id| id as usize)
            .ok_or_else(|| tantivy::TantivyError::InternalError("a document without its id".into()))
    }
}
